"""``certify`` over whole arrays and the live ``Certifier``."""

from __future__ import annotations

import json
from typing import Any, Mapping, Optional

import numpy as np

from . import _native
from ._arrays import samples
from ._config import Config, resolve
from ._errors import ConfigError

#: The gates, in the CSV's order.
GATES = tuple(_native.GATES)
#: The reasons' names: code ``k`` (1 to ``len(REASON_KINDS)``) is ``REASON_KINDS[k - 1]``; code 0 is
#: "open".
REASON_KINDS = tuple(_native.reason_kinds())


class CertifyResult:
    """The evidence of a block of samples, column by column, and the run's summary.

    ``result["beta_hat"]`` (or ``result.beta_hat``) is a numpy array per column of the
    command line's CSV, bit for bit the same numbers (an absent value is NaN): ``t``,
    ``beta_hat`` (eq. betahat), ``rho`` (eq. rho), ``eps`` (eq. eps_est), ``kurtosis``,
    ``spike_fraction``, ``cert_gauss`` (``β̂ − ρ``), ``cert_wass`` (``β̂ − ρ(1 + 2ε)``),
    ``rho_calibrated``, ``cert_calibrated`` (``β̂_w − ρ_w``), ``calibrated_window``,
    ``calibrated_horizon``, ``calibrated_order``, ``cert_nonlinear``, ``nonlinear_window``,
    ``nonlinear_y_lo``, ``nonlinear_y_hi``; per gate ``g`` in ``GATES`` the boolean ``<g>_open`` and the reason code
    ``reason_code_<g>`` (0 open, else ``REASON_KINDS[code - 1]``); the region columns
    ``region_lo_<channel>``, ``region_hi_<channel>``. ``reason_text(g)`` gives the reasons'
    texts, and ``to_pandas()`` the CSV's table.
    """

    def __init__(self, columns: dict[str, np.ndarray], reasons: Any, summary: dict[str, Any],
                 region_names: list[str]) -> None:
        self.columns = columns
        self._reasons = reasons
        self.summary = summary
        self.region_names = region_names

    def __len__(self) -> int:
        return len(self.columns["t"])

    def __getitem__(self, name: str) -> np.ndarray:
        return self.columns[name]

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self.__dict__["columns"][name]
        except KeyError:
            raise AttributeError(name) from None

    def reason_text(self, gate: str) -> np.ndarray:
        """The reasons' texts of ``gate`` (the CSV's ``reason_<gate>``; ``""`` where open)."""
        return np.array(self._reasons.texts(gate), dtype=object)

    @property
    def verdict(self) -> str:
        """The verdict line (the first line of ``certify``'s summary)."""
        return self.summary["verdict"]

    @property
    def certified(self) -> bool:
        """Whether the verdict gate is open after the last sample."""
        return bool(self.summary["certified_at_end"])

    @property
    def paper_only(self) -> bool:
        """``True`` when the run had no calibrated certificate (no stated risk)."""
        return bool(self.summary["paper_only"])

    def to_pandas(self) -> Any:
        """The command line's CSV as a DataFrame: the same columns in the same order (gates
        as booleans, reasons as text), then a ``reason_code_<gate>`` column per gate."""
        import pandas as pd

        data: dict[str, Any] = {}
        for name in _native.EVIDENCE_COLUMNS:
            if name.startswith("reason_"):
                data[name] = self.reason_text(name[len("reason_"):])
            else:
                data[name] = self.columns[name]
        for name in self.region_names:
            data[name] = self.columns[name]
        for g in GATES:
            data[f"reason_code_{g}"] = self.columns[f"reason_code_{g}"]
        return pd.DataFrame(data)

    def __repr__(self) -> str:
        return f"CertifyResult({len(self)} samples; {self.summary['verdict']})"


class Certifier(_native.Certifier):
    """A streaming certifier for live use: the command line's ``certify``, sample by sample.

    ``update(t, y, u)`` certifies one sample (``y``, ``u`` floats or 1-D sequences) and
    returns its ``Evidence``; ``update_many(t, y, u)`` a block (``CertifyResult``), with the
    GIL released while it runs, so certifiers in several threads run in parallel. Both check
    every value as the command line checks a CSV row (``InputDataError`` with the row and
    the column); a block is checked whole before any of it is absorbed.

    ``gates()`` gives every gate's state after the last sample (open, streak, when the
    current opening began, the first opening of the run); ``summary()`` the run's summary
    with the verdict; ``certified`` whether the verdict gate is open now.

    ``checkpoint()`` gives the command line's sealed checkpoint as bytes;
    ``Certifier.restore(data, config)`` resumes from one (a damaged or foreign checkpoint, or
    one of another configuration, raises ``CheckpointError`` with the command line's words).
    Pickling goes through the same checked form.
    """

    def __new__(cls, config: Any = None) -> "Certifier":
        return super().__new__(cls, resolve(config)._native)

    @property
    def config(self) -> Config:  # type: ignore[override]
        """The configuration."""
        return Config._wrap(super().config)

    def update_many(self, t: Any, y: Any, u: Any) -> CertifyResult:
        """Certify a block: ``t`` (n), ``y`` (n × p or n), ``u`` (n × m or n)."""
        cfg = self.config
        t, y, u = samples(t, y, u, len(cfg.outputs), len(cfg.inputs))
        columns, reasons = self.update_block(t, y, u)
        return CertifyResult(columns, reasons, self.summary(), self.region_names)

    def summary(self) -> dict[str, Any]:
        """The run's summary (``certify --summary FILE``'s object): ``verdict``,
        ``certified_at_end``, ``paper_only``, ``first_deploy_*``, ``share_*_gate_open``,
        ``calibrated_reasons``, ``calibrated_region``, counts."""
        return json.loads(self.summary_json())

    @classmethod
    def restore(cls, data: bytes, config: Any = None) -> "Certifier":  # type: ignore[override]
        """Resume from ``checkpoint()``'s bytes (or a ``certify --checkpoint`` file's) for
        ``config``; raises ``CheckpointError`` as ``certify --resume`` refuses."""
        obj = cls(config)
        obj.load(bytes(data))
        return obj

    def __reduce__(self) -> Any:
        return (_unpickle, (bytes(self.checkpoint()), self.config.toml))


def _unpickle(data: bytes, toml: str) -> Certifier:
    return Certifier.restore(data, Config.from_toml_str(toml))


def _labels(x: Any) -> Optional[list[str]]:
    """A pandas DataFrame's column names or a named Series' name; ``None`` otherwise."""
    columns = getattr(x, "columns", None)
    if columns is not None and hasattr(x, "to_numpy"):
        return [str(c) for c in columns]
    name = getattr(x, "name", None)
    if name is not None and hasattr(x, "to_numpy") and not isinstance(x, np.ndarray):
        return [str(name)]
    return None


def certify(
    t: Any, y: Any, u: Any, config: Any = None, *, names: Optional[Mapping[str, Any]] = None
) -> CertifyResult:
    """Certify whole arrays: ``streamcert certify`` on the same data, as numbers.

    ``t`` (n) in seconds, strictly increasing; ``y`` of shape (n, p) or (n,); ``u`` of shape
    (n, m) or (n,); ``config`` a ``Config``, a dict of sections or a TOML path, giving at
    least the candidate gain and the margin (``{"controller": {"gain": [[-1.5]]},
    "certificate": {"margin": 0.05}}``; without them ``ConfigError`` names them). Every other
    key defaults to the command line's (the calibrated certificate with its guards).
    Integer and float32 arrays are converted to float64; see ``streamcert._arrays`` for what
    is refused. The verdict is ``result.verdict``; every evidence column is ``result[name]``.

    The names the verdict and the region columns use: ``names`` (``{"outputs": [...],
    "inputs": [...], "time": ...}``, each optional; a string is one column), else a pandas
    Series' name or a DataFrame's columns, else the configuration's ``columns``.
    """
    cfg = resolve(config)
    given = dict(names or {})
    unknown = set(given) - {"outputs", "inputs", "time"}
    if unknown:
        raise ConfigError(f"names: unknown key(s) {sorted(unknown)}; use outputs, inputs, time")
    for key in ("outputs", "inputs"):
        if isinstance(given.get(key), str):
            given[key] = [given[key]]
    rename = {
        "outputs": given.get("outputs", _labels(y)),
        "inputs": given.get("inputs", _labels(u)),
        "time": given.get("time", (_labels(t) or [None])[0]),
    }
    current = {"outputs": cfg.outputs, "inputs": cfg.inputs, "time": cfg.time}
    if any(v is not None and v != current[k] for k, v in rename.items()):
        cfg = cfg.with_names(**rename)
    t_arr = np.asarray(t)
    if t_arr.ndim == 1 and t_arr.shape[0] == 0:
        from ._errors import ShapeError

        raise ShapeError("no samples: an empty input cannot be certified")
    return Certifier(cfg).update_many(t, y, u)
