"""Threads give the sequential results; configurations from kwargs, dicts and files agree
and are refused with the command line's words."""

from __future__ import annotations

import subprocess
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import streamcert


def _run(seed: int):
    d = streamcert.simulate_g5(1, seed, steps=4000)
    r = streamcert.certify(d["t"], d["y"][:, 1], d["u"][:, 1])
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
    a = streamcert.Config(regression={"window": 200}, certificate={"margin": 0.1})
    b = streamcert.Config({"regression": {"window": np.int64(200)}, "certificate": {"margin": 0.1}})
    path = tmp_path / "c.toml"
    path.write_text(a.toml)
    c = streamcert.Config.from_toml(path)
    assert a.toml == b.toml
    d = streamcert.simulate_g5(1, 1, steps=600)
    runs = [streamcert.certify(d["t"], d["y"][:, 1], d["u"][:, 1], cfg) for cfg in (a, b, c)]
    for r in runs[1:]:
        assert np.array_equal(r["cert_calibrated"], runs[0]["cert_calibrated"], equal_nan=True)


def test_the_default_is_the_clis_with_every_guard():
    text = streamcert.Config().toml
    assert "hidden_dynamics" not in text or "hidden_dynamics = true" in text
    cfg = streamcert.Config()
    assert not cfg.paper_only and cfg.margin == 0.05
    assert cfg.outputs == ["y_b"] and cfg.inputs == ["u_b"]


def test_refusals_carry_the_clis_message(tmp_path, cli):
    path = tmp_path / "bad.toml"
    path.write_text(streamcert.DEFAULT_CONFIG.replace("window = 150 ", "window = 10 "))
    cli_err = subprocess.run([cli, "certify", "--config", str(path), "--input", "/dev/null"],
                             capture_output=True, text=True)
    assert cli_err.returncode == 2
    with pytest.raises(streamcert.ConfigError) as e:
        streamcert.Config.from_toml(path)
    assert str(e.value) in cli_err.stderr
    with pytest.raises(streamcert.ConfigError, match="unknown field"):
        streamcert.Config(regression={"windw": 100})
    with pytest.raises(streamcert.ConfigError, match="m × p"):
        streamcert.Config(columns={"outputs": ["a", "b"]})
    with pytest.raises(streamcert.ConfigError, match="None"):
        streamcert.Config(regression={"window": None})
