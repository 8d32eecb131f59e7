"""Threads give the sequential results; configurations from kwargs, dicts and files agree
and are refused with the command line's words."""

from __future__ import annotations

import subprocess
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import streamcert
from conftest import G5


def _run(seed: int):
    d = streamcert.simulate_g5(1, seed, steps=4000)
    r = streamcert.certify(d["t"], d["y"][:, 1], d["u"][:, 1], G5)
    return r["cert_calibrated"], r.summary


def test_threads_give_the_sequential_results():
    seeds = list(range(4))
    sequential = [_run(s) for s in seeds]
    with ThreadPoolExecutor(max_workers=4) as pool:
        threaded = list(pool.map(_run, seeds))
    for (a, sa), (b, sb) in zip(sequential, threaded):
        assert np.array_equal(a, b, equal_nan=True)
        assert sa == sb


def test_kwargs_dict_and_file_give_one_configuration(tmp_path):
    a = streamcert.Config(regression={"window": 200}, certificate={"margin": 0.1}, controller={"gain": [[-4.0]]})
    b = streamcert.Config({"regression": {"window": np.int64(200)}, "certificate": {"margin": 0.1},
                           "controller": {"gain": np.array([[-4.0]])}})
    path = tmp_path / "c.toml"
    path.write_text(a.toml)
    c = streamcert.Config.from_toml(path)
    assert a.toml == b.toml
    d = streamcert.simulate_g5(1, 1, steps=600)
    runs = [streamcert.certify(d["t"], d["y"][:, 1], d["u"][:, 1], cfg) for cfg in (a, b, c)]
    for r in runs[1:]:
        assert np.array_equal(r["cert_calibrated"], runs[0]["cert_calibrated"], equal_nan=True)


def test_the_default_is_the_clis_with_every_guard():
    text = streamcert.Config(G5).toml
    assert "hidden_dynamics" not in text or "hidden_dynamics = true" in text
    cfg = streamcert.Config(G5)
    assert not cfg.paper_only and cfg.margin == 0.05
    assert cfg.outputs == ["y"] and cfg.inputs == ["u"] and cfg.time == "t"
    two = streamcert.Config(controller={"gain": [[1.0, 2.0]] * 3}, certificate={"margin": 0.1})
    assert two.outputs == ["y1", "y2"] and two.inputs == ["u1", "u2", "u3"]
    # The CLI's keys and defaults, once the required keys are set.
    assert streamcert.Config.from_toml_str(streamcert.G5_NODE_B_CONFIG).toml == streamcert.G5_NODE_B_CONFIG


def test_a_forgotten_gain_or_margin_is_refused_naming_it():
    t, y, u = np.arange(300) * 0.02, np.sin(np.arange(300) * 0.1), np.cos(np.arange(300) * 0.1)
    for call in (lambda: streamcert.certify(t, y, u), lambda: streamcert.Certifier(),
                 lambda: streamcert.Config()):
        with pytest.raises(streamcert.ConfigError) as e:
            call()
        assert "controller.gain" in str(e.value) and "certificate.margin" in str(e.value)
        assert "columns." not in str(e.value)  # arrays carry no headers: named for the caller
    with pytest.raises(streamcert.ConfigError, match="controller.gain") as e:
        streamcert.certify(t, y, u, {"certificate": {"margin": 0.05}})
    assert "certificate.margin" not in str(e.value)
    with pytest.raises(streamcert.ConfigError, match="certificate.margin"):
        streamcert.Config(controller={"gain": [[-1.5]]})
    with pytest.raises(streamcert.ConfigError, match="controller.gain"):
        streamcert.Config.from_toml_str(streamcert.DEFAULT_CONFIG)


def test_the_verdict_names_the_gain_the_margin_and_the_callers_columns():
    pd = pytest.importorskip("pandas")
    d = streamcert.simulate_g5(1, 6)
    df = pd.DataFrame({"time": d["t"], "level": d["y"][:, 1], "pump": d["u"][:, 1]})
    r = streamcert.certify(df["time"], df["level"], df["pump"], G5)
    assert "for K = [[-4]] at the margin 0.05 /s" in r.verdict, r.verdict
    if r.certified:
        assert "level in [" in r.verdict, r.verdict
    assert any("level" in name for name in r.columns if name.startswith("region")), r.columns
    named = streamcert.certify(d["t"], d["y"][:, 1], d["u"][:, 1], G5, names={"outputs": "level"})
    assert np.array_equal(named["cert_calibrated"], r["cert_calibrated"], equal_nan=True)
    assert named.verdict == r.verdict
    with pytest.raises(streamcert.ConfigError, match="names"):
        streamcert.certify(d["t"], d["y"][:, 1], d["u"][:, 1], G5, names={"output": "level"})


def test_refusals_carry_the_clis_message(tmp_path, cli):
    path = tmp_path / "bad.toml"
    path.write_text(streamcert.G5_NODE_B_CONFIG.replace("window = 150 ", "window = 10 "))
    cli_err = subprocess.run([cli, "certify", "--config", str(path), "--input", "/dev/null"],
                             capture_output=True, text=True)
    assert cli_err.returncode == 2
    with pytest.raises(streamcert.ConfigError) as e:
        streamcert.Config.from_toml(path)
    assert str(e.value) in cli_err.stderr
    with pytest.raises(streamcert.ConfigError, match="unknown field"):
        streamcert.Config(G5, regression={"windw": 100})
    with pytest.raises(streamcert.ConfigError, match="m × p"):
        streamcert.Config(G5, columns={"outputs": ["a", "b"]})
    with pytest.raises(streamcert.ConfigError, match="None"):
        streamcert.Config(G5, regression={"window": None})
    # A dict's error names the key's path, not a line of a TOML text the caller never saw.
    with pytest.raises(streamcert.ConfigError, match="`regression.windw`") as e:
        streamcert.Config(G5, regression={"windw": 100})
    assert "line" not in str(e.value)
