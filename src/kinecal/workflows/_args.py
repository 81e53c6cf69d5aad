"""Checks of what a Python caller hands the public workflow functions: a wrong type or
shape is refused at the door with a :class:`~kinecal.errors.ConfigError` (a
``ValueError``) naming the argument, what it got and what was expected, instead of an
``AttributeError`` or ``IndexError`` deep inside (the command line never passes such
values; a script does)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from kinecal.errors import ConfigError

_HOW = {
    "RobotDescription": "kinecal.robot.load_robot(NAME or FILE)",
    "Measurements": "kinecal.io.read_measurements(FILE, robot)",
    "CalibratedModel": "kinecal.io.load_model(FILE)",
}


def _got(value: Any) -> str:
    text = repr(value)
    return type(value).__name__ + (f" {text}" if len(text) <= 40 else "")


def need(value: Any, cls: type | tuple[type, ...], name: str) -> None:
    """Refuse ``value`` unless it is a ``cls`` (naming how to make one)."""
    if not isinstance(value, cls):
        kinds = cls if isinstance(cls, tuple) else (cls,)
        what = " or ".join(k.__name__ for k in kinds)
        how = _HOW.get(what)
        raise ConfigError(
            f"{name}: expected a {what}"
            + (f" (from {how})" if how else "")
            + f"; got {_got(value)}."
        )


def need_robot(robot: Any, name: str = "robot") -> None:
    from kinecal.robot import RobotDescription

    need(robot, RobotDescription, name)


def need_model(cal: Any, name: str = "cal") -> None:
    from kinecal.measurement import CalibratedModel

    need(cal, CalibratedModel, name)


def need_measurements(meas: Any, n_joints: int | None, name: str = "meas") -> None:
    """A Measurements object with ``n_joints`` joint columns (None: any)."""
    from kinecal.measurement import Measurements

    need(meas, Measurements, name)
    n = meas.q_ctrl.shape[1]
    if n_joints is not None and n != n_joints:
        raise ConfigError(
            f"{name} ({meas.source}): {n} joints per row, but the robot has "
            f"{n_joints}; expected measurements of that robot."
        )


def choice(value: Any, allowed: Iterable[str], name: str) -> str:
    """``value``, one of ``allowed``."""
    options = tuple(allowed)
    if not isinstance(value, str) or value not in options:
        raise ConfigError(
            f"{name}: expected one of {', '.join(options)}; got {_got(value)}."
        )
    return value


def words(value: Any, allowed: Iterable[str], name: str) -> tuple[str, ...]:
    """A tuple of names from ``allowed``: a sequence of them, or one string of them
    separated by commas (as the command line takes them)."""
    options = tuple(allowed)
    items = value.split(",") if isinstance(value, str) else value
    try:
        out = tuple(items)
    except TypeError:
        raise ConfigError(
            f"{name}: expected some of {', '.join(options)}; got {_got(value)}."
        ) from None
    for w in out:
        if not isinstance(w, str) or w not in options:
            raise ConfigError(
                f"{name}: expected some of {', '.join(options)}; got {_got(w)}."
            )
    return out


def count(value: Any, name: str, low: int = 1) -> int:
    """An integer >= ``low`` (not a bool, a float or a string)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name}: expected an integer >= {low}; got {_got(value)}.")
    if value < low:
        raise ConfigError(f"{name}: expected an integer >= {low}; got {value}.")
    return int(value)


def joint_rows(q: Any, n_joints: int, name: str) -> np.ndarray:
    """Joint values as an (N, n_joints) array of finite numbers."""
    try:
        a = np.asarray(q, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{name}: expected an (N, {n_joints}) array of joint values; got {_got(q)}."
        ) from None
    if a.ndim != 2 or a.shape[1] != n_joints or a.shape[0] < 1:
        raise ConfigError(
            f"{name}: expected an (N, {n_joints}) array of joint values, one row per "
            f"pose; got shape {a.shape}."
        )
    bad = np.argwhere(~np.isfinite(a))
    if bad.size:
        i, j = bad[0]
        raise ConfigError(
            f"{name}[{i}, {j}]: expected a finite joint value; got {a[i, j]}."
        )
    return a
