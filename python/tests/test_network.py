"""NetworkCertifier against the command line's network; simulate_g5 against simulate g5."""

from __future__ import annotations

import csv
import io
import subprocess

import numpy as np
import pytest

import streamcert
from conftest import same_bits


def test_network_equals_the_cli(tmp_path, cli):
    d = streamcert.simulate_g5(2, 3, bidirectional=True, gamma=0.1)
    t, y, u = d["t"], d["y"], d["u"]
    data, cfg_path = tmp_path / "g5.csv", tmp_path / "net.toml"
    with open(data, "w") as f:
        f.write("t,y_a,u_a,y_b,u_b\n")
        for k in range(len(t)):
            f.write(",".join(repr(float(v)) for v in (t[k], y[k, 0], u[k, 0], y[k, 1], u[k, 1])) + "\n")
    cfg_path.write_text(streamcert.NETWORK_EXAMPLE_CONFIG)
    out = subprocess.run([cli, "network", "--config", str(cfg_path), "--input", str(data)],
                         check=True, capture_output=True, text=True).stdout
    rows = list(csv.DictReader(io.StringIO(out)))
    net = streamcert.NetworkCertifier.from_toml(cfg_path)
    assert net.subsystems == ["A", "B"]
    reports = []
    for k in range(len(t)):
        reports += net.update("A", t[k:k + 1], y[k:k + 1, 0], u[k:k + 1, 0])
        reports += net.update(1, t[k:k + 1], y[k:k + 1, 1], u[k:k + 1, 1])
    assert len(reports) == len(rows) > 10
    for r, row in zip(reports, rows):
        assert same_bits(r["t"], float(row["t"]))
        rate = float(row["rate"]) if row["rate"] else np.nan
        assert same_bits(np.nan if r["rate"] is None else r["rate"], rate)
        assert r["open"] == (row["open"] == "1")
    assert any(r["rate"] is not None for r in reports)


def test_network_config_refusals_are_the_clis():
    bad = streamcert.NETWORK_EXAMPLE_CONFIG.replace('from = "B"', 'from = "C"')
    with pytest.raises(streamcert.ConfigError, match="`C`"):
        streamcert.NetworkCertifier.from_toml_str(bad)
    with pytest.raises(streamcert.ConfigError, match="no subsystem `Z`"):
        streamcert.NetworkCertifier.from_toml_str(streamcert.NETWORK_EXAMPLE_CONFIG).update(
            "Z", [0.0], [0.0], [0.0])


def test_simulate_g5_equals_the_cli(cli):
    out = subprocess.run([cli, "simulate", "g5", "--experiment", "2", "--seed", "5"],
                         check=True, capture_output=True, text=True).stdout
    rows = list(csv.DictReader(io.StringIO(out)))
    d = streamcert.simulate_g5(2, 5)
    assert len(rows) == len(d["t"])
    for k in (0, 1, len(rows) // 2, len(rows) - 1):
        r = rows[k]
        assert same_bits(d["t"][k], float(r["t"]))
        assert same_bits(d["y"][k, 1], float(r["y_b"])) and same_bits(d["u"][k, 0], float(r["u_a"]))
        assert same_bits(d["x"][k, 4], float(r["x5"]))
        assert same_bits(d["beta_true"][k, 1], float(r["beta_true_b"]))
    with pytest.raises(streamcert.ConfigError):
        streamcert.simulate_g5(3, 0)
