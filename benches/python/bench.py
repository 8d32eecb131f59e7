"""Speed of the Python package against the command line and a plain numpy baseline, all in
one run (figures in BENCHMARKS.md, "Python package"). Not a test: it asserts nothing about
time, only that the numpy baseline computes the same certificate.

    python benches/python/bench.py [--rows 1000000] [--update-rows 200000] [--numpy-rows 20000]

Needs the package installed (``pip install ./python``) and the release binary
(``cargo build --release -p streamcert-cli``).
"""

from __future__ import annotations

import argparse
import pathlib
import subprocess
import tempfile
import time

import numpy as np

import streamcert

ROOT = pathlib.Path(__file__).resolve().parents[2]
CLI = ROOT / "target" / "release" / "streamcert"
# The user's choices for G5's node b (the configuration requires them): its columns in the
# CSV of `streamcert simulate g5`, its gain and margin.
PLANT = {
    "columns": {"time": "t", "outputs": ["y_b"], "inputs": ["u_b"]},
    "controller": {"gain": [[-4.0]]},
    "certificate": {"margin": 0.05},
}
PAPER_ONLY = PLANT | {"calibration": {"enabled": False}}


def best(f, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        s = time.perf_counter()
        f()
        times.append(time.perf_counter() - s)
    return min(times)


def numpy_paper_certificate(t, y, u, window, horizon, ridge, c, gain):
    """The paper's Gaussian certificate recomputed per sample from the window, as a numpy
    user would write it: eq. regressor through the origin, trapezoidal integrals, ridge
    solve, β̂ = −λ_max(sym J_cl) (a scalar here), ρ = c (1 + |K|) RMS(R) / √(λ_min(Z Zᵀ/M) + λ)."""
    n = len(t)
    dt = np.diff(t)
    # The integral over every h-step interval, by the trapezoidal rule (cumulative sums).
    cy = np.concatenate([[0.0], np.cumsum(dt * (y[1:] + y[:-1]) / 2)])
    cu = np.concatenate([[0.0], np.cumsum(dt * (u[1:] + u[:-1]) / 2)])
    q = np.arange(n - horizon)
    zy, zu, dy = cy[q + horizon] - cy[q], cu[q + horizon] - cu[q], y[q + horizon] - y[q]
    beta = np.full(n, np.nan)
    cert = np.full(n, np.nan)
    for k in range(horizon + window - 1, n):
        cols = slice(k - horizon - window + 1, k - horizon + 1)
        Z = np.vstack([zy[cols], zu[cols]])
        D = dy[cols]
        G = Z @ Z.T
        theta = np.linalg.solve(G + ridge * np.eye(2), Z @ D)
        j_cl = theta[0] + theta[1] * gain
        r = D - theta @ Z
        rms = np.sqrt(np.mean(r * r))
        lam = np.linalg.eigvalsh(G / window)[0]
        rho = c * (1 + abs(gain)) * rms / np.sqrt(lam + ridge)
        beta[k] = -j_cl
        cert[k] = -j_cl - rho
    return beta, cert


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--update-rows", type=int, default=200_000)
    ap.add_argument("--numpy-rows", type=int, default=20_000)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()

    d = streamcert.simulate_g5(1, 1, steps=a.rows)
    t, y, u = d["t"], d["y"][:, 1], d["u"][:, 1]
    n = len(t)
    with tempfile.TemporaryDirectory() as tmp:
        csv = pathlib.Path(tmp) / "big.csv"
        with open(csv, "w") as f:
            subprocess.run([CLI, "simulate", "g5", "--experiment", "1", "--seed", "1",
                            "--steps", str(a.rows)], stdout=f, check=True)
        print(f"## certify, {n} rows (G5 node b), best of {a.repeat}")
        print("| configuration | CLI on the CSV | Python on arrays | Python rows/s ÷ CLI rows/s |")
        print("|---|---|---|---|")
        for label, sections in (("paper-only", PAPER_ONLY), ("the default", PLANT)):
            cfg = streamcert.Config(sections)
            path = pathlib.Path(tmp) / "c.toml"
            path.write_text(cfg.toml)
            cli = best(lambda: subprocess.run(
                [CLI, "certify", "--config", str(path), "--input", str(csv), "--output",
                 "/dev/null"], check=True, capture_output=True), a.repeat)
            py = best(lambda: streamcert.certify(t, y, u, cfg), a.repeat)
            print(f"| {label} | {cli:.2f} s ({n / cli / 1e6:.2f} M rows/s) | {py:.2f} s "
                  f"({n / py / 1e6:.2f} M rows/s) | {cli / py:.2f} |")

    m = a.update_rows
    print(f"\n## update per call against the block's per-sample time, {m} samples")
    print("| configuration | `update` per call | `update_many` per sample | difference |")
    print("|---|---|---|---|")
    tl, yl, ul = t[:m].tolist(), y[:m].tolist(), u[:m].tolist()
    for label, sections in (("paper-only", PAPER_ONLY), ("the default", PLANT)):
        cfg = streamcert.Config(sections)

        def per_call():
            c = streamcert.Certifier(cfg)
            upd = c.update
            for k in range(m):
                upd(tl[k], yl[k], ul[k])

        one = best(per_call, a.repeat) / m
        block = best(lambda: streamcert.Certifier(cfg).update_many(t[:m], y[:m], u[:m]),
                     a.repeat) / m
        print(f"| {label} | {one * 1e9:.0f} ns | {block * 1e9:.0f} ns | "
              f"{(one - block) * 1e9:+.0f} ns |")

    k = a.numpy_rows
    cfg = streamcert.Config(PAPER_ONLY | {"regression": {
        "model": "through_origin", "input_integral": "trapezoidal"}})
    window, horizon, ridge, c, gain = 150, 5, 1e-4, 0.1, -4.0
    s = time.perf_counter()
    beta_np, cert_np = numpy_paper_certificate(t[:k], y[:k], u[:k], window, horizon, ridge, c, gain)
    numpy_time = time.perf_counter() - s
    ours = best(lambda: streamcert.certify(t[:k], y[:k], u[:k], cfg), a.repeat)
    r = streamcert.certify(t[:k], y[:k], u[:k], cfg)
    ok = np.isfinite(r["beta_hat"]) & np.isfinite(beta_np)
    err = np.max(np.abs(r["cert_gauss"][ok] - cert_np[ok]) / np.maximum(1.0, np.abs(cert_np[ok])))
    assert ok.sum() > k // 2 and err < 1e-6, f"the numpy baseline disagrees: {err}"
    print(f"\n## the paper's certificate, {k} rows: plain numpy recomputed per sample against "
          "streamcert (through the origin, trapezoidal, paper-only)")
    print("| implementation | time | rows/s | ratio |")
    print("|---|---|---|---|")
    print(f"| numpy, recomputed per sample | {numpy_time:.2f} s | {k / numpy_time:,.0f} | 1 |")
    print(f"| `streamcert.certify` | {ours * 1e3:.1f} ms | {k / ours:,.0f} | "
          f"{numpy_time / ours:.0f}× faster |")
    print(f"(largest relative difference of the Gaussian certificates: {err:.1e})")


if __name__ == "__main__":
    main()
