"""``Config``: a ``certify`` configuration with the command line's keys, defaults and
refusals."""

from __future__ import annotations

import json
import os
from typing import Any, Mapping, Optional, Union

import numpy as np

from . import _native


def _plain(x: Any) -> Any:
    """numpy values as plain Python values, for JSON."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


def _names(prefix: str, n: int) -> list[str]:
    return [prefix] if n == 1 else [f"{prefix}{i + 1}" for i in range(n)]


def _with_column_names(merged: dict[str, Any]) -> None:
    """Name the columns the caller left unnamed after the gain's shape (``y``, ``u``, or
    ``y1..yp``, ``u1..um``; time ``t``): arrays carry no headers, so only the gain and the
    margin are the caller's to give."""
    controller = merged.get("controller")
    gain = controller.get("gain") if isinstance(controller, Mapping) else None
    rows = gain if isinstance(gain, list) and gain else [[0.0]]
    m = len(rows)
    p = len(rows[0]) if isinstance(rows[0], list) and rows[0] else 1
    given = merged.get("columns")
    columns = dict(given) if isinstance(given, Mapping) else {}
    columns.setdefault("time", "t")
    columns.setdefault("outputs", _names("y", p))
    columns.setdefault("inputs", _names("u", m))
    merged["columns"] = columns


class Config:
    """A validated ``certify`` configuration.

    Built from keyword arguments or a dict of sections laid over the command line's template
    (``streamcert certify --print-config``), or from a TOML file read exactly as the command
    line reads it. The candidate gain ``controller.gain`` and the ``certificate.margin`` are
    required (a ``ConfigError`` names whichever is missing); the columns are named ``y``,
    ``u`` (``y1..yp``, ``u1..um``) unless given, and ``certify`` uses a pandas Series' or
    DataFrame's own names. Sections merge key by key, so every other key takes the command
    line's default: the calibrated certificate with its three guards (risk ``delta = 0.01``
    over the run), the zero-order hold, the affine model, the gate held for 10 samples.
    Every refusal is a ``ConfigError`` with the command line's message.

    The paper-only mode (its two certificates, no stated risk) is asked for by name:
    ``Config(calibration={"enabled": False})``; ``paper_only`` then says so.

    Examples
    --------
    >>> cfg = Config(controller={"gain": [[-2.5]]}, certificate={"margin": 0.05},
    ...              regression={"window": 200})
    >>> cfg2 = Config({"controller": {"gain": [[-2.5]]}, "certificate": {"margin": 0.1}})
    >>> cfg3 = Config.from_toml("plant.toml")
    """

    __slots__ = ("_native",)

    def __init__(self, sections: Optional[Mapping[str, Any]] = None, /, **kwargs: Any) -> None:
        merged: dict[str, Any] = dict(_plain(sections or {}))
        for k, v in kwargs.items():
            merged[k] = _plain(v)
        _with_column_names(merged)
        self._native = _native.Config.from_json(json.dumps(merged, allow_nan=True))

    @classmethod
    def from_toml(cls, path: Union[str, os.PathLike]) -> "Config":
        """Read a configuration file as ``streamcert certify --config PATH`` does."""
        with open(path, encoding="utf-8") as f:
            text = f.read()
        return cls._wrap(_native.Config.from_toml(text, os.fspath(path)))

    @classmethod
    def from_toml_str(cls, text: str) -> "Config":
        """Read a configuration's TOML text as the command line reads a file."""
        return cls._wrap(_native.Config.from_toml(text, "configuration"))

    @classmethod
    def _wrap(cls, native: Any) -> "Config":
        obj = cls.__new__(cls)
        obj._native = native
        return obj

    @property
    def toml(self) -> str:
        """The TOML text the command line would read to get this configuration."""
        return self._native.toml

    @property
    def outputs(self) -> list[str]:
        """Output column names (``p`` of them)."""
        return self._native.outputs

    @property
    def inputs(self) -> list[str]:
        """Input column names (``m`` of them)."""
        return self._native.inputs

    @property
    def time(self) -> str:
        """The time column's name."""
        return self._native.time

    def with_names(
        self,
        outputs: Optional[list[str]] = None,
        inputs: Optional[list[str]] = None,
        time: Optional[str] = None,
    ) -> "Config":
        """This configuration with its columns renamed (``None`` keeps a name): the names
        the verdict, the evidence's region columns and the checkpoint use."""
        return Config._wrap(self._native.with_columns(
            None if time is None else str(time),
            None if outputs is None else [str(v) for v in outputs],
            None if inputs is None else [str(v) for v in inputs],
        ))

    @property
    def paper_only(self) -> bool:
        """``True`` in the paper-only mode: the verdict then carries no stated risk."""
        return self._native.paper_only

    @property
    def margin(self) -> float:
        """The deployment margin."""
        return self._native.margin

    @property
    def order(self) -> int:
        """The loop model's order, ``regression.order``: 1 the paper's first-order model (the
        default), 2 or 3 a closed loop of that order read through one output (a tank behind
        a tank, a mass read by its position, a plant behind a sensor lag)."""
        return self._native.order

    def __reduce__(self) -> Any:
        return (Config.from_toml_str, (self.toml,))

    def __repr__(self) -> str:
        mode = "paper-only, NO STATED RISK" if self.paper_only else "calibrated"
        return f"Config(outputs={self.outputs}, inputs={self.inputs}, {mode}, order {self.order})"


def resolve(config: Any) -> Config:
    """``config`` as a ``Config``: a mapping is laid over the template, a path is a TOML file;
    ``None`` is refused naming the required keys (the gain and the margin)."""
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, Mapping):
        return Config(config)
    if isinstance(config, (str, os.PathLike)):
        return Config.from_toml(config)
    raise TypeError(f"config must be a Config, a dict or a TOML path, not {type(config).__name__}")
