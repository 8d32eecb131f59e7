"""``regression.order = 2`` from Python: a plant whose output is not its whole state.

The loop ``ÿ + 1.2 ẏ + y = u + 0.1`` (the measured output and its hidden rate of change)
under ``u = K y_m + d`` is simulated exactly (zero-order hold) at 100 Hz for 40 s, ``d`` a
dither of ±0.1 redrawn every second, sensor noise ``σ = 0.01``. At ``K = 0.7625`` the closed
loop is ``(s + 0.25)(s + 0.95)``, five times the margin 0.05; at ``K = 0.948025`` it is
``(s + 0.045)(s + 1.155)``, just below it.
"""

from __future__ import annotations

import numpy as np
import pytest

import streamcert
from conftest import G5

DT = 0.01


def _expm(m: np.ndarray) -> np.ndarray:
    """The matrix exponential of a small matrix of norm well below 1 (Taylor, 30 terms)."""
    out = np.eye(len(m))
    term = np.eye(len(m))
    for k in range(1, 30):
        term = term @ m / k
        out = out + term
    return out


def _loop(gain: float, seed: int, samples: int = 4000):
    """``(t, y_m, u)`` of the loop above under ``gain``."""
    # The state (y, ẏ + 1.2 y) in observable form, the input and the constant: one exact step.
    big = np.zeros((4, 4))
    big[0, 0], big[0, 1], big[1, 0], big[1, 2], big[1, 3] = -1.2, 1.0, -1.0, 1.0, 0.1
    step = _expm(big * DT)
    rng = np.random.default_rng(seed)
    x = np.zeros(4)
    t, y, u = np.arange(samples) * DT, np.empty(samples), np.empty(samples)
    dither = 0.1
    for k in range(samples):
        if k % 100 == 0:
            dither = 0.1 if rng.random() < 0.5 else -0.1
        y[k] = x[0] + 0.01 * rng.standard_normal()
        u[k] = gain * y[k] + dither
        x[2], x[3] = u[k], 1.0
        x = step @ x
    return t, y, u


def _config(gain: float, order: int = 2, window: int = 2000, horizon: int = 50):
    return streamcert.Config({
        "controller": {"gain": [[gain]]},
        "certificate": {"margin": 0.05, "consecutive": 10},
        "regression": {"order": order, "window": window, "horizon": horizon},
    })


def test_the_order_reads_from_a_mapping_and_shows_in_the_config():
    cfg = _config(0.7625)
    assert cfg.order == 2
    assert "order 2" in repr(cfg)
    # The first order is the default.
    assert streamcert.Config(G5).order == 1


def test_a_loop_of_order_two_at_five_times_the_margin_is_certified_with_its_order():
    t, y, u = _loop(0.7625, seed=1)
    r = streamcert.certify(t, y, u, _config(0.7625))
    assert r.certified
    assert r.verdict.startswith("verdict: CERTIFIED")
    assert "calibrated certificate of order 2" in r.verdict
    opened = np.flatnonzero(r["calibrated_open"])
    # The first look comes when the window of 2000 rows is full (n h = 100 samples in).
    assert opened.size and t[opened[0]] >= (2000 + 100 - 1) * DT
    assert np.all(r["cert_calibrated"][opened] >= 0.05)
    # The paper's two certificates are of the first order: not computed at order 2.
    first_order_only = streamcert.REASON_KINDS.index("first_order_only") + 1
    assert np.all(r["reason_code_gauss"] == first_order_only)
    assert np.all(r["reason_code_wass"] == first_order_only)


def test_a_loop_just_below_the_margin_is_not_certified():
    for seed in range(3):
        t, y, u = _loop(0.948025, seed=10 + seed)
        r = streamcert.certify(t, y, u, _config(0.948025))
        assert not np.any(r["calibrated_open"]), seed
        assert not r.certified


def test_what_order_two_does_not_support_is_refused_by_its_key():
    with pytest.raises(streamcert.ConfigError, match="min_rows"):
        _config(0.7625, window=100)
    with pytest.raises(streamcert.ConfigError):
        _config(0.7625, order=4)
