"""Conversions of numpy, pandas and list inputs to the C-contiguous float64 arrays the
extension module reads.

What is converted and what is refused (each refusal a ``ShapeError`` naming the argument):

- float64: used as is (a copy only when not C-contiguous);
- float16 and float32: converted to float64 (exact);
- signed and unsigned integers: converted to float64 (exact up to 2**53 in magnitude;
  larger values are refused, they would be rounded);
- object arrays whose items are numbers: converted; any other object array is refused;
- booleans, complex numbers, strings, bytes, datetimes and timedeltas: refused (a time
  column of datetimes must first be turned into seconds, for example
  ``(t - t[0]) / np.timedelta64(1, "s")``);
- pandas Series and DataFrames: their values (``to_numpy()``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._errors import ShapeError

_EXACT = float(2**53)


def as_float64(x: Any, name: str) -> np.ndarray:
    """``x`` as a C-contiguous float64 array, by the rules of this module."""
    if hasattr(x, "to_numpy") and not isinstance(x, np.ndarray):
        x = x.to_numpy()
    try:
        a = np.asarray(x)
    except (TypeError, ValueError) as e:
        raise ShapeError(f"{name}: not an array of numbers ({e})") from None
    kind = a.dtype.kind
    if kind == "f":
        out = a.astype(np.float64, copy=False)
    elif kind in "iu":
        if a.size and float(np.max(np.abs(a.astype(np.float64)))) > _EXACT:
            raise ShapeError(
                f"{name}: integers beyond 2**53 in magnitude would be rounded by the float64 "
                "conversion; convert them yourself if that is what you mean"
            )
        out = a.astype(np.float64)
    elif kind == "O":
        try:
            out = a.astype(np.float64)
        except (TypeError, ValueError) as e:
            raise ShapeError(f"{name}: an object array whose items are not all numbers ({e})") from None
    elif kind == "b":
        raise ShapeError(f"{name}: booleans are not measurements; convert them to numbers")
    elif kind == "c":
        raise ShapeError(f"{name}: complex numbers are refused (the certificates are real)")
    elif kind in "Mm":
        raise ShapeError(
            f"{name}: datetimes are refused; give seconds, for example "
            '(t - t[0]) / np.timedelta64(1, "s")'
        )
    else:
        raise ShapeError(f"{name}: an array of {a.dtype} is not an array of numbers")
    return np.ascontiguousarray(out, dtype=np.float64)


def samples(t: Any, y: Any, u: Any, p: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``t`` (n), ``y`` (n × p) and ``u`` (n × m) as float64 arrays; a 1-D ``y`` or ``u`` is
    one column. Shapes and lengths are checked against each other and against ``p``, ``m``."""
    t = as_float64(t, "t")
    y = as_float64(y, "y")
    u = as_float64(u, "u")
    if t.ndim != 1:
        raise ShapeError(f"t must be 1-D (one time per sample), got shape {t.shape}")
    n = t.shape[0]
    out = []
    for name, a, width in (("y", y, p), ("u", u, m)):
        if a.ndim == 1:
            a = a.reshape(-1, 1)
        if a.ndim != 2:
            raise ShapeError(f"{name} must be 1-D or 2-D (samples × columns), got shape {a.shape}")
        if a.shape[0] != n:
            raise ShapeError(f"{name} has {a.shape[0]} rows but t has {n} times")
        if a.shape[1] != width:
            raise ShapeError(
                f"{name} has {a.shape[1]} columns but the configuration has {width} "
                f"({'outputs' if name == 'y' else 'inputs'}); name them in "
                f"columns={{'outputs': [...], 'inputs': [...]}}"
            )
        out.append(np.ascontiguousarray(a))
    return t, out[0], out[1]
