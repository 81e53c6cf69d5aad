"""Pose files of ``kinecal plan`` and ``kinecal simulate --plan``: joint columns (and a
sensor's target) read and checked against the joint limits, and written back."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from kinecal.errors import DataError
from kinecal.io import Table, Targets
from kinecal.measurement import CalibratedModel, Measurements
from kinecal.robot import RobotDescription
from kinecal.workflows._args import need_robot

__all__ = ["pose_lines", "read_pose_file"]

Say = Callable[[str], None]


def _check_planned_robot(path: str, robot: RobotDescription) -> None:
    """A plan written by ``kinecal plan`` for another robot (its PLAN.report.json beside
    it names that robot): its poses are not ``robot``'s, even where they fit its limits."""
    from kinecal.io._json_read import loads

    rep = Path(path).with_suffix(".report.json")
    try:
        planned = loads(rep.read_text(encoding="utf-8")).get("robot")
    except (OSError, ValueError, AttributeError):  # no report, or not a plan's
        return
    if isinstance(planned, str) and planned != robot.name:
        raise DataError(
            f"{path}: planned for {planned} ({rep.name} beside it says so); expected "
            f"poses of {robot.name} (plan them with --robot {robot.name})."
        )


def check_calibration_data(
    cal: CalibratedModel | None,
    q: np.ndarray,
    table: Table,
    path: str,
    robot: RobotDescription | None = None,
    targets: Targets | None = None,
    allow: bool = False,
) -> None:
    """``plan --add --data``: refuse data that are not the calibration's, whose
    information the plan would start from: poses outside the joint ranges the model was
    calibrated on (its file's ``calibrated_joint_range``); measurements (positions in
    the file) that read as such for ``robot`` but whose sets or markers the model has
    not, or that the model misses by more than any calibrated robot does (another
    robot, frame or set-up; they were taken as its poses)."""
    if cal is not None:
        robot = cal.model.robot
        _check_joint_range(cal, q, table, path)
    if robot is None or not {"x_mm", "xc_mm"} & set(table.header):
        return
    from kinecal.io import read_measurements

    meas = read_measurements(
        path, robot, targets, allow_out_of_limits=allow, check=False
    )
    if cal is not None:
        _check_model_fits(cal, meas, path)


def _check_joint_range(
    cal: CalibratedModel, q: np.ndarray, table: Table, path: str
) -> None:
    """The poses lie within the joint ranges of the model's calibration data."""
    robot = cal.model.robot
    try:
        rng = np.asarray(cal.info.get("calibrated_joint_range"), dtype=float)
    except (TypeError, ValueError):
        return
    if rng.shape != (robot.n_joints, 2):
        return
    v = q * np.where(robot.prismatic, 1e3, 180.0 / np.pi)
    slack = np.maximum(0.02 * (rng[:, 1] - rng[:, 0]), 1.0)
    out = (v < rng[:, 0] - slack) | (v > rng[:, 1] + slack)
    if out.any():
        i, j = np.argwhere(out)[0]
        raise DataError(
            f"{path}: line {table.lines[i]}, column j{j + 1}_"
            f"{'mm' if robot.prismatic[j] else 'deg'}: {v[i, j]:.1f} is outside "
            f"{rng[j, 0]:.1f} .. {rng[j, 1]:.1f}, the joint range of the data the model "
            f"was calibrated on ({int(out.any(axis=1).sum())} rows outside); expected "
            "that calibration's data file (--data)."
        )


def _check_model_fits(cal: CalibratedModel, meas: Measurements, path: str) -> None:
    """The model's sets and markers hold the data's, and its median error on them is
    what a calibration leaves (at most ``OTHER_ROBOT_MM``)."""
    from kinecal.io import check_data_for_model
    from kinecal.measurement._calibrated import map_labels
    from kinecal.workflows._evaluate import OTHER_ROBOT_MM

    meas, _ = check_data_for_model(meas, cal)
    spec, hint = cal.model.spec, " Expected that calibration's data file (--data)."
    for labels, index, own, what in (
        (meas.set_labels, meas.set_index, spec.sets, "set"),
        (meas.marker_labels, meas.marker_index, spec.markers, "marker"),
    ):
        if tuple(labels) != tuple(own):
            map_labels(labels, index, own, what, path, hint=hint)
    err = np.linalg.norm(cal.predict(meas).raw_position, axis=1) * 1e3
    med = float(np.median(err))
    if med > OTHER_ROBOT_MM:
        raise DataError(
            f"{path}: the model's median error on these rows is {med:.1f} mm (expected "
            f"at most {OTHER_ROBOT_MM:g} mm on the data it was calibrated on): "
            f"measurements of another robot, frame or set-up than "
            f"{cal.model.robot.name}'s calibration; expected that calibration's data "
            "file (--data)."
        )


def read_pose_file(
    path: str,
    robot: RobotDescription,
    labels: tuple[str, ...] | None,
    allow: bool | None = None,
    warn: Say | None = None,
) -> tuple[Table, list[str], np.ndarray, np.ndarray | None]:
    """Joint columns (and a sensor's ``target``) of a pose file: (table, cols, q, ti).

    Candidates (``allow`` None) must lie within the limits; measured poses may pass them
    by 1 deg (1 mm), and further with ``allow`` (--allow-out-of-limits: a ``warn``
    line).

    Returns
    -------
    tuple
        The table, its joint columns, the joints (N, n) [rad] and the target
        indices (None without targets).
    """
    from kinecal.io import read_table

    need_robot(robot)
    t = read_table(path)
    _check_planned_robot(path, robot)
    pat = re.compile(r"^j(\d+)_(deg|rad|mm|m)$")
    found = {int(m.group(1)): c for c in t.header if (m := pat.match(c))}
    n = robot.n_joints
    if sorted(found) != list(range(1, n + 1)):
        have = ", ".join(found[k] for k in sorted(found)) or "none"
        raise DataError(
            f"{path}: joint columns {have}; robot {robot.name} needs j1_deg .. j{n}_deg."
        )
    cols = [found[k] for k in range(1, n + 1)]
    q = np.empty((len(t.rows), n))
    for k, c in enumerate(cols):
        q[:, k] = _joint_column(t, c, k, robot, path, allow, warn)
    deg = [k for k, c in enumerate(cols) if c.endswith("_deg")]
    if deg and len(t.rows) >= 5:
        vals = np.degrees(q[:, deg])
        if np.abs(vals).max() <= 2 * np.pi + 1e-9 and np.ptp(vals, axis=0).max() > 0.05:
            raise DataError(
                f"{path}: columns {cols[deg[0]]}..{cols[deg[-1]]}: every value is within "
                f"±{2 * np.pi:.2f}, which looks like radians; convert to degrees or name "
                "the columns jK_rad."
            )
    ti = None
    if labels is not None and "target" in t.header:
        index = {lab: i for i, lab in enumerate(labels)}
        names = [s.strip() for s in t.column("target")]
        for lab, line in zip(names, t.lines):
            if lab not in index:
                raise DataError(
                    f"{path}: line {line}, column 'target': {lab!r} is not in the "
                    f"targets file ({', '.join(labels)})."
                )
        ti = np.array([index[s] for s in names], np.intp)
    return t, cols, q, ti


def _joint_column(
    t: Table,
    c: str,
    k: int,
    robot: RobotDescription,
    path: str,
    allow: bool | None,
    warn: Say | None,
) -> np.ndarray:
    """Joint ``k``'s values [rad; m] from column ``c``, checked against the limits."""
    lim = robot.limits
    unit = c.rsplit("_", 1)[1]
    prismatic = robot.joints[k].kind == "prismatic"
    if prismatic != (unit in ("mm", "m")):
        want = f"j{k + 1}_mm" if prismatic else f"j{k + 1}_deg"
        raise DataError(f"{path}: column '{c}': joint {k + 1} needs {want}.")
    f = {"deg": np.pi / 180, "rad": 1.0, "mm": 1e-3, "m": 1.0}[unit]
    q = t.numbers(c) * f
    slack = 1e-9 if allow is None else (1e-3 if prismatic else np.pi / 180)
    bad = np.flatnonzero((q < lim[k, 0] - slack) | (q > lim[k, 1] + slack))
    if bad.size and allow:
        if warn is not None:
            warn(
                f"warning   {path}: {bad.size} rows with {c} beyond the limits of "
                f"{robot.name} (first: line {t.lines[bad[0]]}), accepted as asked."
            )
    elif bad.size:
        i = int(bad[0])
        g = 1.0 / f
        raise DataError(
            f"{path}: line {t.lines[i]}, column '{c}': {q[i] * g:.6g} is outside "
            f"the joint limits [{lim[k, 0] * g:.6g}, {lim[k, 1] * g:.6g}] of "
            f"{robot.name}"
            + ("." if allow is None else " (use --allow-out-of-limits to accept).")
        )
    return q


def pose_lines(
    robot: RobotDescription,
    q: np.ndarray,
    ti: np.ndarray | None,
    labels: tuple[str, ...] | None,
) -> list[str]:
    """CSV lines of poses (j1_deg..jN_deg, a sensor's target)."""
    cols = [
        f"j{k + 1}_mm" if j.kind == "prismatic" else f"j{k + 1}_deg"
        for k, j in enumerate(robot.joints)
    ]
    f = np.array([1e3 if j.kind == "prismatic" else 180 / np.pi for j in robot.joints])
    lines = [",".join(cols + (["target"] if ti is not None else []))]
    for i, row in enumerate(q * f):
        cells = [f"{v:.6f}" for v in row]
        if ti is not None and labels is not None:
            cells.append(labels[ti[i]])
        lines.append(",".join(cells))
    return lines
