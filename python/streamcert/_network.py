"""``NetworkCertifier``: many subsystems' certificates composed into a network verdict."""

from __future__ import annotations

import json
import os
from typing import Any, Mapping, Union

from . import _native
from ._arrays import samples
from ._config import _plain


class NetworkCertifier:
    """The command line's ``streamcert network``: one certifier per subsystem and the
    composer. Samples go in by subsystem (``update(name, t, y, u)``, a block at a time);
    every epoch the composer reaches comes out as its report, a dict with the keys of the
    command line's epoch row (``t``, ``epoch``, ``local``, ``estimated``, ``rate``,
    ``certified``, ``open``, ``critical_scale``, ``participation``, ``limiting_subsystem``,
    ``limiting_coupling``, ``not_certified``, ...).

    ``config`` is the network configuration: a dict with the TOML file's keys
    (``NETWORK_EXAMPLE_CONFIG``; ``streamcert network --print-config`` is its template), or use
    ``NetworkCertifier.from_toml(path)``. Its defaults are the command line's: the calibrated
    certificates, composed at risk ``delta`` split over the subsystems.
    """

    def __init__(self, config: Mapping[str, Any]) -> None:
        self._native = _native.NetworkCertifier.from_json(json.dumps(_plain(config)))

    @classmethod
    def from_toml(cls, path: Union[str, os.PathLike]) -> "NetworkCertifier":
        """Read a ``network`` configuration file as the command line does."""
        with open(path, encoding="utf-8") as f:
            return cls.from_toml_str(f.read(), os.fspath(path))

    @classmethod
    def from_toml_str(cls, text: str, name: str = "configuration") -> "NetworkCertifier":
        """Read a ``network`` configuration's TOML text."""
        obj = cls.__new__(cls)
        obj._native = _native.NetworkCertifier.from_toml(text, name)
        return obj

    @property
    def subsystems(self) -> list[str]:
        """The subsystems' names."""
        return self._native.subsystems

    def update(self, subsystem: Union[str, int], t: Any, y: Any, u: Any) -> list[dict[str, Any]]:
        """Feed one subsystem (by name or index) a block; the epochs composed meanwhile."""
        i = subsystem if isinstance(subsystem, int) else self._native.index(subsystem)
        dims = self._native.dims
        if not 0 <= i < len(dims):
            raise IndexError(f"subsystem index {i} out of range ({len(dims)} subsystems)")
        p, m = dims[i]
        t, y, u = samples(t, y, u, p, m)
        return json.loads(self._native.update_block(i, t, y, u))

    def advance(self, t: float) -> list[dict[str, Any]]:
        """Compose every epoch up to ``t`` (a clock tick: silent subsystems turn stale)."""
        return json.loads(self._native.advance(float(t)))
