"""Exception hierarchy of kinecal.

Every error a user can trigger with bad input derives from :class:`CalibError`, so the
CLI can catch one type and turn it into a one-line message and a non-zero exit code.
"""

from __future__ import annotations

__all__ = [
    "CalibError",
    "ConfigError",
    "DataError",
    "IdentifiabilityError",
    "ModelError",
    "OutputClosed",
    "described",
    "expect_type",
]


class CalibError(Exception):
    """Base class of all kinecal errors."""


class ConfigError(CalibError, ValueError):
    """A robot description, model file or option is invalid."""


class DataError(CalibError, ValueError):
    """A measurement file or array is invalid (missing column, NaN, wrong units...)."""


class ModelError(CalibError, ValueError):
    """A model cannot be built or evaluated as asked (unknown parameter, wrong size)."""


class IdentifiabilityError(CalibError, ValueError):
    """The data cannot determine the model asked for (too few poses, rank too low)."""


class OutputClosed(Exception):
    """The reader of a command's output went away (``kinecal robots | head -1``): the
    command stops; exit 141, as SIGPIPE (docs/errors.md). Raised from the
    ``BrokenPipeError`` of the write, which click itself would turn into exit 1."""


def expect_type(
    value: object, cls: type | tuple[type, ...], name: str, how: str = ""
) -> None:
    """ConfigError naming the argument ``name`` unless ``value`` is a ``cls`` (what a
    script hands a public function; ``how``: where one comes from)."""
    if not isinstance(value, cls):
        kinds = cls if isinstance(cls, tuple) else (cls,)
        raise ConfigError(
            f"{name}: expected a {' or '.join(k.__name__ for k in kinds)}"
            + (f" (from {how})" if how else "")
            + f"; got {described(value)}."
        )


def described(value: object) -> str:
    """A value as a message names it: its type, and its repr when short."""
    text = repr(value)
    return type(value).__name__ + (f" {text}" if len(text) <= 40 else "")
