"""``Config``: a ``certify`` configuration with the command line's keys, defaults and
refusals."""

from __future__ import annotations

import json
import os
from typing import Any, Mapping, Optional, Union

import numpy as np

from . import _native


def _plain(x: Any) -> Any:
    """numpy values as plain Python values, for JSON."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, Mapping):
        return {str(k): _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    return x


class Config:
    """A validated ``certify`` configuration.

    Built from keyword arguments or a dict of sections laid over the command line's defaults
    (``streamcert certify --print-config``), or from a TOML file read exactly as the command
    line reads it. Sections merge key by key, so ``Config()`` is the default: the calibrated
    certificate with its three guards (risk ``delta = 0.01`` over the run), the zero-order
    hold, the affine model, margin 0.05 held for 10 samples, one output ``y_b``, one input
    ``u_b`` and the candidate gain ``K = [[-4.0]]``. Every refusal is a ``ConfigError`` with
    the command line's message.

    The paper-only mode (its two certificates, no stated risk) is asked for by name:
    ``Config(calibration={"enabled": False})``; ``paper_only`` then says so.

    Examples
    --------
    >>> cfg = Config(controller={"gain": [[-2.5]]}, regression={"window": 200})
    >>> cfg2 = Config({"certificate": {"margin": 0.1}})
    >>> cfg3 = Config.from_toml("plant.toml")
    """

    __slots__ = ("_native",)

    def __init__(self, sections: Optional[Mapping[str, Any]] = None, /, **kwargs: Any) -> None:
        merged: dict[str, Any] = dict(_plain(sections or {}))
        for k, v in kwargs.items():
            merged[k] = _plain(v)
        self._native = _native.Config.from_json(json.dumps(merged, allow_nan=True))

    @classmethod
    def from_toml(cls, path: Union[str, os.PathLike]) -> "Config":
        """Read a configuration file as ``streamcert certify --config PATH`` does."""
        with open(path, encoding="utf-8") as f:
            text = f.read()
        return cls._wrap(_native.Config.from_toml(text, os.fspath(path)))

    @classmethod
    def from_toml_str(cls, text: str) -> "Config":
        """Read a configuration's TOML text as the command line reads a file."""
        return cls._wrap(_native.Config.from_toml(text, "configuration"))

    @classmethod
    def _wrap(cls, native: Any) -> "Config":
        obj = cls.__new__(cls)
        obj._native = native
        return obj

    @property
    def toml(self) -> str:
        """The TOML text the command line would read to get this configuration."""
        return self._native.toml

    @property
    def outputs(self) -> list[str]:
        """Output column names (``p`` of them)."""
        return self._native.outputs

    @property
    def inputs(self) -> list[str]:
        """Input column names (``m`` of them)."""
        return self._native.inputs

    @property
    def paper_only(self) -> bool:
        """``True`` in the paper-only mode: the verdict then carries no stated risk."""
        return self._native.paper_only

    @property
    def margin(self) -> float:
        """The deployment margin."""
        return self._native.margin

    def __reduce__(self) -> Any:
        return (Config.from_toml_str, (self.toml,))

    def __repr__(self) -> str:
        mode = "paper-only, NO STATED RISK" if self.paper_only else "calibrated"
        return f"Config(outputs={self.outputs}, inputs={self.inputs}, {mode})"


def resolve(config: Any) -> Config:
    """``config`` as a ``Config``: ``None`` is the default, a mapping is laid over it, a path
    is a TOML file."""
    if config is None:
        return Config()
    if isinstance(config, Config):
        return config
    if isinstance(config, Mapping):
        return Config(config)
    if isinstance(config, (str, os.PathLike)):
        return Config.from_toml(config)
    raise TypeError(f"config must be a Config, a dict or a TOML path, not {type(config).__name__}")
