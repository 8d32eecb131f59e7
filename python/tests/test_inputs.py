"""Every bad input raises its exception (one test per input); conversions give the same
numbers; hypothesis on where a bad value sits."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import streamcert
from conftest import G5, node_b


@pytest.fixture(scope="module")
def data(g5):
    t, y, u = node_b(g5, 300)
    return t.copy(), y.copy(), u.copy()


def test_nan_names_row_and_column(data):
    t, y, u = data
    y = y.copy()
    y[42] = np.nan
    with pytest.raises(streamcert.InputDataError) as e:
        streamcert.certify(t, y, u, G5)
    assert (e.value.row, e.value.column) == (42, "y")
    assert "NaN and infinity are not accepted" in str(e.value)


def test_infinity_names_row_and_column(data):
    t, y, u = data
    u = u.copy()
    u[7] = -np.inf
    with pytest.raises(streamcert.InputDataError) as e:
        streamcert.certify(t, y, u, G5)
    assert (e.value.row, e.value.column) == (7, "u")


def test_non_increasing_time(data):
    t, y, u = data
    t = t.copy()
    t[10] = t[9]
    with pytest.raises(streamcert.InputDataError, match="duplicated time") as e:
        streamcert.certify(t, y, u, G5)
    assert (e.value.row, e.value.column) == (10, "t")
    t[10] = t[9] - 1.0
    with pytest.raises(streamcert.InputDataError, match="before the previous time"):
        streamcert.certify(t, y, u, G5)


def test_wrong_shapes(data):
    t, y, u = data
    with pytest.raises(streamcert.ShapeError, match="2 columns but the configuration has 1"):
        streamcert.certify(t, np.stack([y, y], axis=1), u, G5)
    with pytest.raises(streamcert.ShapeError, match="1-D or 2-D"):
        streamcert.certify(t, y.reshape(-1, 1, 1), u, G5)
    with pytest.raises(streamcert.ShapeError, match="t must be 1-D"):
        streamcert.certify(t.reshape(-1, 1), y, u, G5)


def test_wrong_lengths(data):
    t, y, u = data
    with pytest.raises(streamcert.ShapeError, match="rows but t has"):
        streamcert.certify(t, y[:-1], u, G5)
    with pytest.raises(streamcert.ShapeError):
        streamcert.Certifier(G5).update(0.0, [1.0, 2.0], 0.0)


def test_empty_arrays():
    with pytest.raises(streamcert.ShapeError, match="no samples"):
        streamcert.certify(np.array([]), np.array([]), np.array([]), G5)


def test_integer_arrays_are_converted(data):
    t, y, u = data
    ti, yi, ui = np.arange(len(t)), np.round(y * 100).astype(np.int32), np.round(u * 100).astype(np.int64)
    a = streamcert.certify(ti, yi, ui, G5)
    b = streamcert.certify(ti.astype(float), yi.astype(float), ui.astype(float), G5)
    assert np.array_equal(a["beta_hat"], b["beta_hat"], equal_nan=True)
    with pytest.raises(streamcert.ShapeError, match="2\\*\\*53"):
        streamcert.certify(ti, yi.astype(np.int64) * 2**60, ui, G5)


def test_float32_arrays_are_converted(data):
    t, y, u = data
    a = streamcert.certify(t, y.astype(np.float32), u.astype(np.float32), G5)
    b = streamcert.certify(t, y.astype(np.float32).astype(float), u.astype(np.float32).astype(float), G5)
    assert np.array_equal(a["cert_calibrated"], b["cert_calibrated"], equal_nan=True)


def test_non_contiguous_arrays_give_the_same_result(data):
    t, y, u = data
    wide = np.asfortranarray(np.stack([u, y, u], axis=1))
    a = streamcert.certify(t, wide[:, 1], wide[:, ::2][:, 0], G5)
    b = streamcert.certify(t, y, u, G5)
    assert np.array_equal(a["beta_hat"], b["beta_hat"], equal_nan=True)
    strided_t = np.repeat(t, 2)[::2]
    c = streamcert.certify(strided_t, y, u, G5)
    assert np.array_equal(c["beta_hat"], b["beta_hat"], equal_nan=True)


def test_object_arrays(data):
    t, y, u = data
    a = streamcert.certify(t, np.array(list(y), dtype=object), u, G5)
    assert np.array_equal(a["beta_hat"], streamcert.certify(t, y, u, G5)["beta_hat"], equal_nan=True)
    bad = np.array(list(y), dtype=object)
    bad[3] = "pump"
    with pytest.raises(streamcert.ShapeError, match="not all numbers"):
        streamcert.certify(t, bad, u, G5)


def test_booleans_complex_strings_datetimes_are_refused(data):
    t, y, u = data
    with pytest.raises(streamcert.ShapeError, match="booleans"):
        streamcert.certify(t, y > 0, u, G5)
    with pytest.raises(streamcert.ShapeError, match="complex"):
        streamcert.certify(t, y + 1j, u, G5)
    with pytest.raises(streamcert.ShapeError):
        streamcert.certify(t, y.astype(str), u, G5)
    stamps = np.datetime64("2026-01-01") + (t * 1e3).astype("timedelta64[ms]")
    with pytest.raises(streamcert.ShapeError, match="timedelta64"):
        streamcert.certify(stamps, y, u, G5)


def test_pandas_inputs(data):
    pd = pytest.importorskip("pandas")
    t, y, u = data
    df = pd.DataFrame({"t": t, "y_b": y, "u_b": u})
    a = streamcert.certify(df["t"], df[["y_b"]], df["u_b"], G5)
    assert np.array_equal(a["beta_hat"], streamcert.certify(t, y, u, G5)["beta_hat"], equal_nan=True)


def test_a_refused_block_leaves_the_certifier_as_it_was(data):
    t, y, u = data
    c = streamcert.Certifier(G5)
    c.update_many(t[:100], y[:100], u[:100])
    before = bytes(c.checkpoint())
    bad = y[100:].copy()
    bad[50] = np.nan
    with pytest.raises(streamcert.InputDataError) as e:
        c.update_many(t[100:], bad, u[100:])
    assert e.value.row == 50
    assert bytes(c.checkpoint()) == before


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 299), st.sampled_from([np.nan, np.inf, -np.inf]), st.sampled_from(["t", "y", "u"]))
def test_any_bad_value_is_reported_where_it_is(data, row, value, where):
    t, y, u = (a.copy() for a in data)
    {"t": t, "y": y, "u": u}[where][row] = value
    with pytest.raises(streamcert.InputDataError) as e:
        streamcert.certify(t, y, u, G5)
    assert e.value.row == row
    assert e.value.column == {"t": "t", "y": "y", "u": "u"}[where]


@settings(max_examples=20, deadline=None)
@given(st.lists(st.integers(1, 299), max_size=6))
def test_any_split_into_blocks_gives_the_whole_run(data, cuts):
    t, y, u = data
    bounds = [0, *sorted(set(cuts)), len(t)]
    whole = streamcert.certify(t, y, u, G5)
    c = streamcert.Certifier(G5)
    parts = [c.update_many(t[a:b], y[a:b], u[a:b]) for a, b in zip(bounds, bounds[1:])]
    got = np.concatenate([p["cert_calibrated"] for p in parts])
    assert np.array_equal(got, whole["cert_calibrated"], equal_nan=True)
    assert c.summary() == whole.summary
