"""Shared fixtures: G5 data, the command line's binary, CSV round trips."""

from __future__ import annotations

import csv
import io
import os
import pathlib
import subprocess

import numpy as np
import pytest

import streamcert

ROOT = pathlib.Path(__file__).resolve().parents[2]

#: The required keys for node b of G5: the paper's gain and margin.
G5 = {"controller": {"gain": [[-4.0]]}, "certificate": {"margin": 0.05}}


@pytest.fixture(scope="session")
def cli() -> str:
    """The ``streamcert`` binary of this workspace (``STREAMCERT_BIN``, or built with cargo;
    the tests that compare with it are skipped, saying how to build it, where neither is
    available)."""
    path = os.environ.get("STREAMCERT_BIN")
    if path:
        return path
    exe = ROOT / "target" / "release" / "streamcert"
    build = ["cargo", "build", "--release", "-q", "-p", "streamcert-cli"]
    try:
        subprocess.run(build, cwd=ROOT, check=True)
    except (OSError, subprocess.CalledProcessError) as e:
        if exe.exists():
            return str(exe)
        pytest.skip(
            f"these tests compare with the command line, which could not be built ({e}): run "
            f"`{' '.join(build)}` in the repository, or set STREAMCERT_BIN to a streamcert binary"
        )
    return str(exe)


@pytest.fixture(scope="session")
def g5() -> dict:
    return streamcert.simulate_g5(1, 0)


def node_b(d: dict, n: int | None = None):
    k = slice(0, n)
    return d["t"][k], d["y"][k, 1], d["u"][k, 1]


def write_csv(path: pathlib.Path, t, y, u) -> None:
    # repr(float) is the shortest round trip: the CLI reads back the same doubles.
    with open(path, "w") as f:
        f.write("t,y_b,u_b\n")
        for a, b, c in zip(t, y, u):
            f.write(f"{float(a)!r},{float(b)!r},{float(c)!r}\n")


def read_csv(text: str) -> tuple[list[str], list[list[str]]]:
    rows = list(csv.reader(io.StringIO(text)))
    return rows[0], rows[1:]


def same_bits(a: float, b: float) -> bool:
    return (np.isnan(a) and np.isnan(b)) or np.float64(a).tobytes() == np.float64(b).tobytes()
