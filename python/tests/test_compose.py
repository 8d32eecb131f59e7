"""compose against Lemma 1's closed form and the command line's compose."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import streamcert

rate = st.floats(0.01, 10.0)


@settings(max_examples=60, deadline=None)
@given(rate, rate, st.floats(0.0, 10.0))
def test_compose_equals_lemma1_for_two_subsystems(a, b, g):
    c = streamcert.compose([a, b], [[0.0, g], [g, 0.0]])
    closed = (a + b) / 2 - math.sqrt((a - b) ** 2 / 4 + g * g)
    assert streamcert.lemma1(a, b, g) == pytest.approx(closed, rel=1e-12, abs=1e-12)
    assert c.rate == pytest.approx(closed, rel=1e-9, abs=1e-9)
    assert c.rate <= closed + 1e-12 * max(a, b, g, 1.0)  # the safe end
    assert c.contracting == (c.rate > 0)
    assert (g < streamcert.warning_gain(a, b)) == (closed > 0) or abs(closed) < 1e-9


def test_compose_equals_the_cli_on_the_same_files():
    rng = np.random.default_rng(7)
    n = 12
    beta = rng.uniform(0.5, 3.0, n)
    gains = rng.uniform(0.0, 0.2, (n, n)) * (rng.random((n, n)) < 0.4)
    np.fill_diagonal(gains, 0.0)
    rates_text = "\n".join(repr(float(b)) for b in beta) + "\n"
    dense_text = "\n".join(",".join(repr(float(x)) for x in row) for row in gains) + "\n"
    i, j = np.nonzero(gains)
    triplet_text = "i,j,gamma\n" + "".join(f"{a},{b},{float(gains[a, b])!r}\n" for a, b in zip(i, j))
    for text, triplets, mine in (
        (dense_text, False, streamcert.compose(beta, gains)),
        (triplet_text, True, streamcert.compose(beta, (i, j, gains[i, j]))),
    ):
        cli = streamcert.cli_compose(rates_text, text, triplets)
        assert cli["rate"] == mine.rate
        assert cli["critical_scale"] == mine.critical_scale
        assert cli["symmetric_rate"] == mine.symmetric_rate
        assert cli["weights"] == list(mine.weights)


def test_scipy_sparse_equals_dense():
    sparse = pytest.importorskip("scipy.sparse")
    beta = np.array([1.0, 2.0, 1.5])
    g = np.array([[0, 0.3, 0], [0.1, 0, 0.2], [0, 0.4, 0]])
    a = streamcert.compose(beta, g)
    b = streamcert.compose(beta, sparse.csr_matrix(g))
    assert a.rate == b.rate and a.limiting_subsystem == b.limiting_subsystem
    assert a.limiting_coupling == b.limiting_coupling


@settings(max_examples=40, deadline=None)
@given(st.integers(2, 8), st.integers(0, 2**32 - 1))
def test_network_rate_is_at_most_the_smallest_local_rate(n, seed):
    rng = np.random.default_rng(seed)
    beta = rng.uniform(0.1, 2.0, n)
    g = rng.uniform(0, 0.5, (n, n))
    np.fill_diagonal(g, 0.0)
    c = streamcert.compose(beta, g)
    assert c.rate <= beta.min() + 1e-12
    assert c.symmetric_rate <= c.rate + 1e-9
    assert c.participation.sum() == pytest.approx(1.0)
    assert 0 <= c.limiting_subsystem < n
    # The exact value, from a dense eigensolver: -max Re eig(Γ).
    exact = -np.max(np.linalg.eigvals(g - np.diag(beta)).real)
    assert c.rate == pytest.approx(exact, abs=1e-9)


def test_invalid_networks_raise_compose_error():
    with pytest.raises(streamcert.ComposeError):
        streamcert.compose([1.0, 1.0], [[0, -0.1], [0, 0]])
    with pytest.raises(streamcert.ComposeError):
        streamcert.compose([1.0, 1.0], [[0, np.nan], [0, 0]])
    with pytest.raises(streamcert.ComposeError):
        streamcert.compose([1.0, 1.0], ([0], [5], [0.1]))
    with pytest.raises(streamcert.ComposeError):
        streamcert.lemma1(-1.0, 1.0, 0.1)
    with pytest.raises(streamcert.ShapeError):
        streamcert.compose([1.0, 1.0, 1.0], [[0, 0.1], [0.1, 0]])
