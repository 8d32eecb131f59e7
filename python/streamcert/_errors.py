"""The exceptions of streamcert: one class per kind of error, all ``StreamcertError``.

Every error the Rust library reports arrives as one of these, never as a crash:

- ``ConfigError`` (also a ``ValueError``): the configuration is refused, with the command
  line's message (the same words ``streamcert certify --config`` prints).
- ``InputDataError`` (also a ``ValueError``): a sample is not valid data (NaN, infinity,
  non-increasing time); ``row`` is its 0-based index in the arrays passed in and ``column``
  the configuration's name of the column at fault (``None`` when no one column is).
- ``ShapeError`` (an ``InputDataError``): arrays of the wrong shape, length or type.
- ``CheckpointError`` (also a ``ValueError``): a checkpoint is damaged, foreign, or was
  written with another configuration.
- ``ComposeError`` (also a ``ValueError``): a network cannot be composed (a negative or
  non-finite gain, a local rate Lemma 1 does not accept, wrong dimensions).
"""

from __future__ import annotations

from typing import Optional


class StreamcertError(Exception):
    """Base class of every streamcert error."""

    row: Optional[int] = None
    column: Optional[str] = None


class ConfigError(StreamcertError, ValueError):
    """The configuration is refused (the command line's message)."""


class InputDataError(StreamcertError, ValueError):
    """A sample is not valid data; ``row`` (0-based) and ``column`` say where."""


class ShapeError(InputDataError):
    """Arrays of the wrong shape, length or type."""


class CheckpointError(StreamcertError, ValueError):
    """A checkpoint is damaged, foreign, or written with another configuration."""


class ComposeError(StreamcertError, ValueError):
    """A network cannot be composed."""
