"""certify and Certifier against the command line, bit for bit; live use; checkpoints."""

from __future__ import annotations

import json
import pickle
import subprocess

import numpy as np
import pytest

import streamcert
from conftest import G5, node_b, read_csv, same_bits, write_csv


def test_version_is_the_crates():
    assert streamcert.__version__.count(".") == 2
    assert streamcert.__version__ == streamcert._native.VERSION


def test_certify_equals_the_cli_bit_for_bit(tmp_path, cli, g5):
    t, y, u = node_b(g5)
    data, cfg_path, summary_path = tmp_path / "g5.csv", tmp_path / "c.toml", tmp_path / "s.json"
    write_csv(data, t, y, u)
    cfg_path.write_text(streamcert.G5_NODE_B_CONFIG)
    out = subprocess.run(
        [cli, "certify", "--config", str(cfg_path), "--input", str(data), "--summary", str(summary_path)],
        check=True, capture_output=True, text=True,
    ).stdout
    header, rows = read_csv(out)
    r = streamcert.certify(t, y, u, streamcert.Config.from_toml(cfg_path))
    assert len(rows) == len(r) == len(t)
    df = r.to_pandas()
    assert list(df.columns[: len(header)]) == header
    for j, name in enumerate(header):
        col = df[name].to_numpy()
        for k in range(len(rows)):
            text = rows[k][j]
            if name.startswith("reason_"):
                assert text == col[k], (name, k)
            elif name.endswith("_open"):
                assert (text == "1") == bool(col[k]), (name, k)
            else:
                v = float(text) if text else np.nan
                assert same_bits(v, float(col[k])), (name, k, text, col[k])
    cli_summary = json.loads(summary_path.read_text())
    assert r.summary == cli_summary
    assert r.verdict.startswith("verdict: CERTIFIED")
    assert r.certified and not r.paper_only


def test_update_one_by_one_and_blocks_equal_certify(g5):
    t, y, u = node_b(g5, 700)
    whole = streamcert.certify(t, y, u, G5)
    c = streamcert.Certifier(G5)
    for k in range(len(t)):
        e = c.update(float(t[k]), float(y[k]), [float(u[k])])
        assert same_bits(e.cert_calibrated if e.cert_calibrated is not None else np.nan,
                         whole["cert_calibrated"][k])
        assert e.calibrated_open == bool(whole["calibrated_open"][k])
        reason = e.reason("calibrated")
        assert (reason is None) == (whole["reason_code_calibrated"][k] == 0)
        if reason is not None:
            assert reason == (whole["reason_code_calibrated"][k], whole.reason_text("calibrated")[k])
    assert c.summary() == whole.summary
    gates = c.gates()
    assert gates["calibrated"]["open"] == bool(whole["calibrated_open"][-1])
    first = whole.summary["first_deploy_calibrated"]
    assert gates["calibrated"]["first_opened_at"] == first
    assert first is None or first == whole["t"][np.argmax(whole["calibrated_open"])]
    c2 = streamcert.Certifier(G5)
    parts = [c2.update_many(t[a:b], y[a:b], u[a:b]) for a, b in [(0, 1), (1, 300), (300, 301), (301, 700)]]
    for name in streamcert._native.FLOAT_COLUMNS:
        joined = np.concatenate([p[name] for p in parts])
        assert np.array_equal(joined, whole[name], equal_nan=True), name


def test_checkpoint_restore_and_pickle_resume_the_run(g5):
    t, y, u = node_b(g5, 600)
    whole = streamcert.certify(t, y, u, G5)
    for cut in (1, 2, 137, 450):
        a = streamcert.Certifier(G5)
        first = a.update_many(t[:cut], y[:cut], u[:cut])
        b = streamcert.Certifier.restore(a.checkpoint(), streamcert.Config(G5))
        c = pickle.loads(pickle.dumps(a))
        for resumed in (b, c):
            rest = resumed.update_many(t[cut:], y[cut:], u[cut:])
            got = np.concatenate([first["cert_calibrated"], rest["cert_calibrated"]])
            assert np.array_equal(got, whole["cert_calibrated"], equal_nan=True), cut
            assert resumed.summary() == whole.summary


def test_a_damaged_or_foreign_checkpoint_is_refused(g5):
    t, y, u = node_b(g5, 100)
    a = streamcert.Certifier(G5)
    a.update_many(t, y, u)
    data = bytearray(a.checkpoint())
    other = streamcert.Config(controller={"gain": [[-4.0]]}, certificate={"margin": 0.1})
    with pytest.raises(streamcert.CheckpointError, match="margin: 0.05 in the checkpoint, 0.1 now"):
        streamcert.Certifier.restore(bytes(data), other)
    data[len(data) // 2] ^= 0x01
    with pytest.raises(streamcert.CheckpointError):
        streamcert.Certifier.restore(bytes(data), streamcert.Config(G5))
    with pytest.raises(streamcert.CheckpointError, match="not a streamcert checkpoint"):
        streamcert.Certifier.restore(b"\xff\xfe\x00", streamcert.Config(G5))
    with pytest.raises(streamcert.CheckpointError):
        streamcert.Certifier.restore(b"", streamcert.Config(G5))


def test_a_cli_checkpoint_resumes_in_python(tmp_path, cli, g5):
    t, y, u = node_b(g5, 500)
    data, cfg_path, cp = tmp_path / "a.csv", tmp_path / "c.toml", tmp_path / "run.ckpt"
    write_csv(data, t[:300], y[:300], u[:300])
    cfg_path.write_text(streamcert.G5_NODE_B_CONFIG)
    subprocess.run([cli, "certify", "--config", str(cfg_path), "--input", str(data),
                    "--output", "/dev/null", "--checkpoint", str(cp)], check=True, capture_output=True)
    c = streamcert.Certifier.restore(cp.read_bytes(), streamcert.Config.from_toml(cfg_path))
    rest = c.update_many(t[300:], y[300:], u[300:])
    whole = streamcert.certify(t, y, u, streamcert.Config.from_toml(cfg_path))
    assert np.array_equal(rest["beta_hat"], whole["beta_hat"][300:], equal_nan=True)
    assert c.summary() == whole.summary


def test_paper_only_mode_says_it_has_no_stated_risk(g5):
    t, y, u = node_b(g5, 400)
    cfg = streamcert.Config(G5, calibration={"enabled": False})
    assert cfg.paper_only and not streamcert.Config(G5).paper_only
    r = streamcert.certify(t, y, u, cfg)
    assert "NO STATED RISK" in r.verdict and r.paper_only
    assert np.all(np.isnan(r["cert_calibrated"]))
