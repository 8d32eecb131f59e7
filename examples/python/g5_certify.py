"""Simulate the paper's G5 benchmark, certify both subsystems, compose them, and draw the run.

    python examples/python/g5_certify.py [--out g5-python.png] [--seed 0]

Runs headless (matplotlib's Agg backend). Experiment 1: K = diag(-3.5, -4.0), subsystem B
drives A through gamma = 0.15 (the paper's cascade).
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import streamcert  # noqa: E402

GAINS = {"a": -3.5, "b": -4.0}
GAMMA = 0.15  # B drives A
MARGIN = 0.05  # the paper's deployment margin (1/s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--out", default="g5-python.png")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    data = streamcert.simulate_g5(experiment=1, seed=args.seed)
    results = {}
    for i, name in enumerate("ab"):
        cfg = streamcert.Config(
            columns={"outputs": [f"y_{name}"], "inputs": [f"u_{name}"]},
            controller={"gain": [[GAINS[name]]]},
            certificate={"margin": MARGIN},
        )
        results[name] = streamcert.certify(data["t"], data["y"][:, i], data["u"][:, i], cfg)
        print(f"subsystem {name}: {results[name].verdict}")

    # The network: compose the local certificates at the last sample where both calibrated
    # gates were open (each certificate then stands at its stated risk).
    both = results["a"]["calibrated_open"] & results["b"]["calibrated_open"]
    if both.any():
        k = int(np.flatnonzero(both)[-1])
        rates = [float(results[n]["cert_calibrated"][k]) for n in "ab"]
        net = streamcert.compose(rates, [[0.0, GAMMA], [0.0, 0.0]])
        print(f"t = {data['t'][k]:.2f} s, both gates open, local certificates "
              f"{rates[0]:.4f} and {rates[1]:.4f}: network rate {net.rate:.4f} "
              f"(contracting: {net.contracting}), critical coupling scale "
              f"{net.critical_scale:.3g}, limiting subsystem {'ab'[net.limiting_subsystem]}; "
              f"Lemma 1 with gamma both ways: {streamcert.lemma1(*rates, GAMMA):.4f}")
    else:
        print("the network is never certified: the two gates are never open together")

    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    margin = MARGIN
    for ax, name in zip(axes[:2], "ab"):
        r = results[name]
        t = r["t"]
        lo = r["cert_calibrated"]
        beta_w = lo + r["rho_calibrated"]
        ax.fill_between(t, lo, beta_w + r["rho_calibrated"], color="tab:blue", alpha=0.2,
                        label="calibrated band  β̂_w ± ρ_w")
        ax.plot(t, r["beta_hat"], color="0.4", lw=0.8, label="β̂ (paper's window)")
        ax.plot(t, lo, color="tab:blue", lw=1.2, label="calibrated certificate")
        ax.plot(t, data["beta_true"][:, "ab".index(name)], color="k", lw=0.8, ls=":",
                label="true local rate")
        ax.axhline(margin, color="tab:red", lw=0.8, ls="--", label=f"margin {margin}")
        opened = r["calibrated_open"]
        ax.fill_between(t, 0, 1, where=opened, transform=ax.get_xaxis_transform(),
                        color="tab:green", alpha=0.12, label="calibrated gate open")
        ax.set_ylabel(f"rate, subsystem {name}")
        ax.set_ylim(-2, 6)
        ax.legend(loc="upper left", fontsize=7, ncol=3)
    axes[2].plot(results["b"]["t"], results["b"]["eps"], color="tab:purple", lw=1.0)
    axes[2].set_ylabel("ε(t), subsystem b")
    axes[2].set_xlabel("t (s)")
    fig.suptitle(f"streamcert on G5, experiment 1, seed {args.seed} (Python)")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
