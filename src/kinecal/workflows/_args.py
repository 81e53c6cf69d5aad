"""Checks of what a Python caller hands the public workflow functions: a wrong type or
shape is refused at the door with a :class:`~kinecal.errors.ConfigError` (a
``ValueError``) naming the argument, what it got and what was expected, instead of an
``AttributeError`` or ``IndexError`` deep inside (the command line never passes such
values; a script does)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from kinecal.errors import ConfigError, described, expect_type

_HOW = {
    "RobotDescription": "kinecal.robot.load_robot(NAME or FILE)",
    "Measurements": "kinecal.io.read_measurements(FILE, robot)",
    "CalibratedModel": "kinecal.io.load_model(FILE)",
}


def need(value: Any, cls: type | tuple[type, ...], name: str) -> None:
    """Refuse ``value`` unless it is a ``cls`` (naming how to make one)."""
    kinds = cls if isinstance(cls, tuple) else (cls,)
    expect_type(value, cls, name, _HOW.get(" or ".join(k.__name__ for k in kinds), ""))


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
            f"{name}: expected one of {', '.join(options)}; got {described(value)}."
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
            f"{name}: expected some of {', '.join(options)}; got {described(value)}."
        ) from None
    for w in out:
        if not isinstance(w, str) or w not in options:
            raise ConfigError(
                f"{name}: expected some of {', '.join(options)}; got {described(w)}."
            )
    return out


def count(value: Any, name: str, low: int = 1) -> int:
    """An integer >= ``low`` (not a bool, a float or a string)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(
            f"{name}: expected an integer >= {low}; got {described(value)}."
        )
    if value < low:
        raise ConfigError(f"{name}: expected an integer >= {low}; got {value}.")
    return int(value)


def joint_rows(q: Any, n_joints: int, name: str) -> np.ndarray:
    """Joint values as an (N, n_joints) array of finite numbers."""
    try:
        a = np.asarray(q, dtype=float)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{name}: expected an (N, {n_joints}) array of joint values; got {described(q)}."
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


def joints_within_limits(
    q: Any, robot: Any, name: str, beyond: bool = False
) -> np.ndarray:
    """:func:`joint_rows` of ``robot``'s joints [rad, m], each within its limits (90
    given in degrees was taken as 90 rad); ``beyond``: within a turn (1 m) of them
    (measured with ``allow_out_of_limits``)."""
    a = joint_rows(q, robot.n_joints, name)
    lim = robot.limits
    slack = np.where(robot.prismatic, 1.0, 2 * np.pi) if beyond else _slack(robot)
    out = np.argwhere((a < lim[:, 0] - slack) | (a > lim[:, 1] + slack))
    if out.size:
        i, j = out[0]
        unit = "m" if robot.prismatic[j] else "rad"
        raise ConfigError(
            f"{name}[{i}, {j}]: {a[i, j]:g} {unit} is beyond the limits "
            f"[{lim[j, 0]:g}, {lim[j, 1]:g}] {unit} of {robot.name} "
            f"{robot.joint_names[j]}; expected controller joints in radians (metres)."
        )
    return a


def plan_arguments(
    setup: Any,
    kinds: tuple[type, type],
    *,
    candidates: Any = None,
    n: Any = None,
    ranges: Any = None,
    measured: Any = None,
) -> None:
    """What a script hands :func:`~kinecal.workflows.plan_candidates` and
    :func:`~kinecal.workflows.plan_measurements`: a PlanSetup, PoseCandidates, a
    count, joint ranges (n, 2) within the limits and measured poses (N, n) [rad]
    (ranges in degrees were clipped to the limits, unsaid: the whole range was
    planned; measured poses in degrees were planned from as radians)."""
    need(setup, kinds[0], "setup")  # kinds: (PlanSetup, PoseCandidates), of _plan
    if candidates is not None:
        need(candidates, kinds[1], "candidates")
    if n is not None:
        count(n, "n")
    robot = setup.robot
    if ranges is not None:
        _joint_ranges(ranges, robot)
    if measured is not None:  # (beyond the limits with allow_out_of_limits)
        joints_within_limits(measured, robot, "measured", beyond=True)


def _joint_ranges(ranges: Any, robot: Any) -> None:
    """(n, 2) [low, high] per joint [rad, m], low <= high, within the limits."""
    try:
        r = np.asarray(ranges, dtype=float)
    except (TypeError, ValueError):
        r = np.zeros(0)
    if r.shape != (robot.n_joints, 2) or not np.all(r[:, 0] <= r[:, 1]):
        raise ConfigError(
            f"ranges: expected ({robot.n_joints}, 2) [low, high] per joint [rad, m] "
            f"with low <= high; got {described(ranges) if r.size == 0 else r.shape}."
        )
    lim, slack = robot.limits, _slack(robot)
    bad = np.flatnonzero((r[:, 0] < lim[:, 0] - slack) | (r[:, 1] > lim[:, 1] + slack))
    if bad.size:
        j = int(bad[0])
        unit = "m" if robot.prismatic[j] else "rad"
        raise ConfigError(
            f"ranges[{j}] ({robot.joint_names[j]}): [{r[j, 0]:g}, {r[j, 1]:g}] {unit} "
            f"reaches beyond the limits [{lim[j, 0]:g}, {lim[j, 1]:g}] {unit}; expected "
            "a range within them, in radians (metres)."
        )


def _slack(robot: Any) -> np.ndarray:
    """How far beyond its limits a joint value may lie (1 deg, 1 mm), as the files'."""
    return np.where(robot.prismatic, 1e-3, np.radians(1.0))
