"""streamcert: streaming contraction certificates for networked nonlinear systems.

Decide, from logged or live plant data, whether a feedback controller may be deployed:

- ``certify(t, y, u, config)``: the command line's ``streamcert certify`` over arrays, every
  evidence column as a numpy array and the verdict (``result.verdict``);
- ``Certifier(config)``: the same, live (``update``, ``update_many``, checkpoints, pickling);
- ``compose(rates, gains)``, ``lemma1``, ``warning_gain``: the network guarantee;
- ``NetworkCertifier(config)``: many subsystems composed at every epoch;
- ``simulate_g5(experiment, seed)``: the paper's benchmark as arrays.

The candidate gain and the margin are yours to give (there is no default for them:
``certify(t, y, u)`` alone raises ``ConfigError`` naming them), for example
``certify(t, y, u, {"controller": {"gain": [[-1.5]]}, "certificate": {"margin": 0.05}})``.
Everything else defaults to the command line's: the calibrated certificate with its guards
(hidden dynamics, nonlinearity, plant change) at risk ``delta = 0.01`` over the run. The
paper's two certificates alone (no stated risk) are a mode asked for by name:
``Config(calibration={"enabled": False})``.
"""

from __future__ import annotations

from typing import Any, Optional

from . import _native
from ._certify import GATES, REASON_KINDS, Certifier, CertifyResult, certify
from ._compose import Composition, cli_compose, compose, lemma1, warning_gain
from ._config import Config
from ._errors import (
    CheckpointError,
    ComposeError,
    ConfigError,
    InputDataError,
    ShapeError,
    StreamcertError,
)
from ._network import NetworkCertifier

__version__: str = _native.VERSION

#: ``streamcert certify --print-config``: the configuration template, commented; its five
#: required keys (columns, gain, margin) read ``"REQUIRED"`` and are refused until set.
DEFAULT_CONFIG: str = _native.DEFAULT_CONFIG
#: The template with the required keys set for node b of G5 (``simulate_g5``'s ``y[:, 1]``,
#: ``u[:, 1]`` as columns ``y_b``, ``u_b``; the paper's gain ``[[-4.0]]``, margin 0.05): the
#: project's examples' configuration, not a default.
G5_NODE_B_CONFIG: str = _native.G5_NODE_B_CONFIG
#: An example network configuration for G5's two subsystems, commented (``streamcert network
#: --print-config`` writes it with the columns, gains and margins as ``"REQUIRED"``).
NETWORK_EXAMPLE_CONFIG: str = _native.NETWORK_EXAMPLE_CONFIG
Evidence = _native.Evidence


def simulate_g5(
    experiment: int = 1,
    seed: int = 0,
    *,
    steps: Optional[int] = None,
    gamma: Optional[float] = None,
    bidirectional: bool = False,
) -> dict[str, Any]:
    """Run ``seed`` of the paper's G5 experiment (1 or 2): the data of
    ``streamcert simulate g5 --experiment E --seed S`` as arrays, a dict with ``t`` (n),
    ``y`` = (y_a, y_b), ``u`` = (u_a, u_b), ``beta_true`` (the true local rates, n × 2) and
    the states ``x`` (n × 5). ``steps`` and ``gamma`` replace the experiment's; the coupling
    is the paper's cascade unless ``bidirectional``."""
    return _native.simulate_g5(int(experiment), int(seed), steps, gamma, bool(bidirectional))


__all__ = [
    "DEFAULT_CONFIG",
    "GATES",
    "NETWORK_EXAMPLE_CONFIG",
    "REASON_KINDS",
    "CheckpointError",
    "Certifier",
    "CertifyResult",
    "Composition",
    "ComposeError",
    "Config",
    "ConfigError",
    "Evidence",
    "InputDataError",
    "NetworkCertifier",
    "ShapeError",
    "StreamcertError",
    "certify",
    "cli_compose",
    "compose",
    "lemma1",
    "simulate_g5",
    "warning_gain",
    "__version__",
]
