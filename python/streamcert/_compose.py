"""Composition: local rates and coupling gains in, the network guarantee out."""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from . import _native
from ._arrays import as_float64
from ._errors import ShapeError


@dataclass(frozen=True)
class Composition:
    """The network guarantee of local rates ``β_i`` and coupling gains ``γ_ij`` (``j`` drives
    ``i``), the matrix ``Γ = −diag β + Γ_off``.

    ``rate`` is ``−α(Γ)`` (its safe end; the network contracts iff it is positive);
    ``weights`` the Perron weights ``η_i`` of the norm ``Σ η_i x_i²`` that attains it (dense)
    or the Collatz–Wielandt certificate vector (sparse); ``symmetric_rate`` the unweighted
    bound ``λ_min(diag β − sym Γ_off)`` (Lemma 1's form for N subsystems); ``critical_scale``
    ``s* = 1/ρ(D⁻¹ Γ_off)`` (every coupling scaled by ``s`` keeps contraction iff
    ``s < s*``); ``participation`` each subsystem's share ``p_i = w_i v_i / (wᵀ v)``;
    ``limiting_subsystem`` the subsystem the rate depends on most and ``limiting_coupling``
    the coupling ``(i, j)`` with the largest share.
    """

    rate: float
    contracting: bool
    weights: np.ndarray
    symmetric_rate: Optional[float]
    critical_scale: float
    participation: np.ndarray
    limiting_subsystem: int
    limiting_coupling: Optional[tuple[int, int]]
    method: str


def _triplets(gains: Any, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if hasattr(gains, "tocoo"):  # a scipy.sparse matrix or array
        coo = gains.tocoo()
        if coo.shape != (n, n):
            raise ShapeError(f"{n} rates need an {n} × {n} gain matrix, got shape {coo.shape}")
        rows, cols, vals = coo.row, coo.col, coo.data
    elif isinstance(gains, tuple) and len(gains) == 3:
        rows, cols, vals = gains
    else:
        g = as_float64(gains, "gains")
        if g.ndim != 2 or g.shape != (n, n):
            raise ShapeError(
                f"{n} rates need an {n} × {n} gain matrix or (i, j, gamma) triplets, "
                f"got shape {g.shape}"
            )
        rows, cols = np.nonzero(g)
        vals = g[rows, cols]
    rows_i = np.ascontiguousarray(np.asarray(rows), dtype=np.int64)
    cols_i = np.ascontiguousarray(np.asarray(cols), dtype=np.int64)
    if rows_i.ndim != 1 or cols_i.ndim != 1:
        raise ShapeError("triplet indices must be 1-D")
    if not (np.array_equal(rows_i, np.asarray(rows)) and np.array_equal(cols_i, np.asarray(cols))):
        raise ShapeError("triplet indices must be integers")
    return rows_i, cols_i, as_float64(vals, "gamma").reshape(-1)


def compose(rates: Any, gains: Any, *, method: str = "auto") -> Composition:
    """The network rate of local rates ``rates`` (N) and coupling gains ``gains``: a dense
    N × N array (entry ``(i, j)`` is how ``j`` drives ``i``; zero diagonal), a tuple of
    triplet arrays ``(i, j, gamma)``, or a scipy.sparse matrix.

    ``method``: ``"auto"`` (dense up to 2000 subsystems, sparse above, as the command line's
    ``compose``), ``"dense"`` or ``"sparse"``. Raises ``ComposeError`` for an invalid network
    (negative or non-finite values, an index out of range, a self-loop).
    """
    beta = as_float64(rates, "rates").reshape(-1)
    rows, cols, vals = _triplets(gains, beta.shape[0])
    dense = {"auto": None, "dense": True, "sparse": False}.get(method, "bad")
    if dense == "bad":
        raise ValueError(f"method must be 'auto', 'dense' or 'sparse', not {method!r}")
    d = _native.compose(beta, rows, cols, vals, dense)
    lc = d["limiting_coupling"]
    return Composition(
        rate=d["rate"],
        contracting=d["contracting"],
        weights=d["weights"],
        symmetric_rate=d["symmetric_rate"],
        critical_scale=d["critical_scale"],
        participation=d["participation"],
        limiting_subsystem=d["limiting_subsystem"],
        limiting_coupling=None if lc is None else (int(lc[0]), int(lc[1])),
        method=d["method"],
    )


def lemma1(beta_a: float, beta_b: float, gamma: float) -> float:
    """Lemma 1 (eq. beta_net): ``β_net = (β_A + β_B)/2 − √((β_A − β_B)²/4 + γ²)`` for two
    subsystems with rates ``β_A, β_B > 0`` coupled both ways by ``γ ≥ 0``."""
    return _native.lemma1(float(beta_a), float(beta_b), float(gamma))


def warning_gain(beta_a: float, beta_b: float) -> float:
    """The warning gain ``γ_warn = √(β_A β_B)``: Lemma 1's rate is positive iff
    ``γ < γ_warn``."""
    return _native.warning_gain(float(beta_a), float(beta_b))


def cli_compose(rates_text: str, gains_text: str, triplets: bool = False) -> dict[str, Any]:
    """The command line's ``streamcert compose --json`` on the texts of a rates file and a
    gains file (dense matrix, or ``i,j,gamma`` lines with ``triplets``)."""
    return json.loads(_native.cli_compose_json(rates_text, gains_text, triplets))
