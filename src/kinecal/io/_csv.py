"""Measurement and target CSV files of DESIGN §11, validated up front.

Measurement file (header required, units in the names)::

    j1_deg, ..., jN_deg            controller angles (jK_rad also accepted; jK_mm for a
                                   prismatic joint)
    x_mm, y_mm, z_mm               point data: tool point in the user frame
    qw, qx, qy, qz                 optional orientation (w first): pose data
    w_deg, p_deg, r_deg            or the orientation as FANUC W, P, R (= roll, pitch, yaw
                                   about the fixed x, y, z axes: Rz(r) Ry(p) Rx(w))
    target, xc_mm, yc_mm, zc_mm    sensor data: target seen in the cam frame (with --targets)
    set, marker, payload_kg, sigma_mm, sigma_deg   optional

Targets file: ``target, x_mm, y_mm, z_mm[, r_mm]`` (user frame).

Every problem raises :class:`DataError` naming the file, the line and the column; rows that
cannot be right are refused (joint values beyond the robot's limits, a near-miss column
name, a targets file in metres). Findings that do not stop the run (duplicated rows, a
payload beyond the rating, quaternions in x, y, z, w order, poses that do not excite a
joint) are :class:`~kinecal.identification.Diagnostic` records: :func:`read_data` returns
them, :func:`read_measurements` issues them as :class:`DataWarning`.
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinecal._record import Record
from kinecal._stats import median
from kinecal.errors import DataError, expect_type
from kinecal.geometry import quat_wxyz_to_matrix, wpr_to_matrix
from kinecal.io._checks import (
    DataWarning,
    data_diagnostics,
    frozen_orientations,
    near_miss,
)
from kinecal.io._csv_hints import named_joints_hint
from kinecal.io._table import Table, read_table
from kinecal.measurement import Diagnostic, Measurements
from kinecal.robot import RobotDescription
from kinecal.units import deg_to_rad, mm_to_m

__all__ = [
    "Table",
    "Targets",
    "read_data",
    "read_measurements",
    "read_table",
    "read_targets",
]

_OPTIONAL = {"set", "marker", "payload_kg", "sigma_mm", "sigma_deg"}
_POINT = ("x_mm", "y_mm", "z_mm")
_QUAT = ("qw", "qx", "qy", "qz")
_WPR = ("w_deg", "p_deg", "r_deg")
_SENSOR = ("target", "xc_mm", "yc_mm", "zc_mm")
_KNOWN = _OPTIONAL | set(_POINT) | set(_QUAT) | set(_WPR) | set(_SENSOR)
_JOINT_RE = re.compile(r"^j(\d+)_(deg|rad|mm|m)$")
# Columns a user might mean when they forget the unit suffix.
_UNITLESS = {"x", "y", "z", "xc", "yc", "zc", "sigma", "payload", "r"}
# Joint values this far beyond a limit are refused (file units: deg or mm).
LIMIT_MARGIN_DEG, LIMIT_MARGIN_MM = 1.0, 1.0
_TO_FILE = {"deg": 180.0 / np.pi, "rad": 1.0, "mm": 1e3, "m": 1.0}


@dataclass(frozen=True, eq=False, repr=False)
class Targets(Record):
    """Targets known in the user frame (sensor data)."""

    labels: tuple[str, ...]
    p: np.ndarray  # (K, 3) [m]
    radius: np.ndarray | None  # (K,) [m]


def read_targets(path: str | Path) -> Targets:
    """Read a targets file ``target, x_mm, y_mm, z_mm[, r_mm]``.

    Raises
    ------
    DataError
        Missing column, bad value, a label twice, or coordinates (radii) that look like
        metres: targets a few millimetres apart, or spheres under 0.25 mm in radius.
    """
    t = read_table(path)
    for c in ("target", "x_mm", "y_mm", "z_mm"):
        if c not in t.header:
            raise DataError(
                f"{t.path}: missing column '{c}' (need target, x_mm, y_mm, z_mm)."
            )
    labels = [s.strip() for s in t.column("target")]
    seen: dict[str, int] = {}
    for lab, line in zip(labels, t.lines):
        if not lab:
            raise DataError(f"{t.path}: line {line}, column 'target': empty label.")
        if lab in seen:
            raise DataError(
                f"{t.path}: line {line}, column 'target': {lab!r} appears twice."
            )
        seen[lab] = int(line)
    xyz = np.column_stack([t.numbers(c) for c in _POINT])
    _check_far(t, xyz, _POINT)
    r = t.numbers("r_mm") if "r_mm" in t.header else None
    if len(t) >= 2 and np.abs(xyz).max() < 5.0 and np.ptp(xyz, axis=0).max() > 0:
        raise DataError(
            f"{t.path}: columns x_mm, y_mm, z_mm: every target is within 5 of the origin "
            "(targets millimetres apart?), which looks like metres; convert to "
            "millimetres."
        )
    if r is not None and np.any(r <= 0):  # all below 0.25 mm: metres (below)
        i = int(np.flatnonzero(r <= 0)[0])
        raise DataError(
            f"{t.path}: line {t.lines[i]}, column 'r_mm': {r[i]:g}; expected a sphere "
            "radius > 0 mm."
        )
    if r is not None and np.all(r < 0.25):
        raise DataError(
            f"{t.path}: column 'r_mm': every radius is below 0.25, which looks like "
            "metres; convert to millimetres."
        )
    return Targets(tuple(labels), mm_to_m(xyz), None if r is None else mm_to_m(r))


def _labels(t: Table, name: str) -> tuple[np.ndarray, tuple[str, ...]]:
    if name not in t.header:
        return np.zeros(len(t), np.intp), ("",)
    vals = [s.strip() for s in t.column(name)]
    labels = tuple(dict.fromkeys(vals))
    if "" in labels:
        line = t.lines[vals.index("")]
        raise DataError(f"{t.path}: line {line}, column '{name}': empty label.")
    index = {lab: i for i, lab in enumerate(labels)}
    return np.fromiter((index[v] for v in vals), np.intp, len(vals)), labels


def _limits(
    t: Table,
    robot: RobotDescription,
    cols: list[str],
    q: np.ndarray,
    allow: bool,
) -> Diagnostic | None:
    """Refuse joint values beyond the limits (by more than the margin) unless allowed."""
    lim = robot.limits
    margin = np.where(
        robot.prismatic, LIMIT_MARGIN_MM * 1e-3, np.radians(LIMIT_MARGIN_DEG)
    )
    out = (q < lim[:, 0] - margin) | (q > lim[:, 1] + margin)
    if not out.any():
        return None
    i, k = (
        int(x) for x in np.argwhere(out)[0]
    )  # the first line, then the first column
    unit = cols[k].rsplit("_", 1)[1]
    f = _TO_FILE[unit]
    where = (
        f"line {t.lines[i]}, column '{cols[k]}': {t.numbers(cols[k])[i]:.6g} is outside "
        f"the limits [{lim[k, 0] * f:.6g}, {lim[k, 1] * f:.6g}] of {robot.name} J{k + 1}"
    )
    slack = (
        f"{LIMIT_MARGIN_MM:g} mm" if robot.prismatic[k] else f"{LIMIT_MARGIN_DEG:g} deg"
    )
    if not allow:
        raise DataError(
            f"{t.path}: {where} (by more than {slack}): wrong robot, joint zero or units? "
            "Use --allow-out-of-limits (allow_out_of_limits=True) to accept such rows."
        )
    # Even when asked: a turn beyond a revolute joint's limits (a stroke, and at least
    # 100 mm, beyond a prismatic one's) is no joint value at all (1e300, a wrong column).
    far = np.where(robot.prismatic, np.maximum(lim[:, 1] - lim[:, 0], 0.1), 2.0 * np.pi)
    wild = (q < lim[:, 0] - far) | (q > lim[:, 1] + far)
    if wild.any():
        i, k = (int(x) for x in np.argwhere(wild)[0])
        unit = cols[k].rsplit("_", 1)[1]
        f = _TO_FILE[unit]
        raise DataError(
            f"{t.path}: line {t.lines[i]}, column '{cols[k]}': "
            f"{t.numbers(cols[k])[i]:.6g} is not a joint value of {robot.name} J{k + 1} "
            f"(limits [{lim[k, 0] * f:.6g}, {lim[k, 1] * f:.6g}]; even "
            "--allow-out-of-limits accepts at most a turn, or a stroke, beyond them)."
        )
    rows = np.flatnonzero(out.any(axis=1))
    per_joint = ", ".join(
        f"J{j + 1} ({int(out[:, j].sum())})"
        for j in range(q.shape[1])
        if out[:, j].any()
    )
    return Diagnostic(
        "out_of_limits",
        f"{t.path}: {rows.size} rows beyond the joint limits of {robot.name} (rows per "
        f"joint: {per_joint}; first: {where}), accepted as asked.",
        rows=tuple(int(t.lines[r]) for r in rows),
        stage="data",
    )


def _joint_columns(
    t: Table, robot: RobotDescription, allow_out_of_limits: bool = False
) -> tuple[list[str], np.ndarray, Diagnostic | None]:
    found: dict[int, str] = {}
    for c in t.header:
        m = _JOINT_RE.match(c)
        if m:
            k = int(m.group(1))
            if k in found:
                raise DataError(
                    f"{t.path}: joint {k} appears twice ({found[k]!r}, {c!r})."
                )
            found[k] = c
    n = robot.n_joints
    if not found:
        raise DataError(
            f"{t.path}: no joint columns; expected j1_deg .. j{n}_deg for {robot.name}"
            + named_joints_hint(t.header, robot)
            + "."
        )
    if max(found) != n or len(found) != n:
        have = ", ".join(found[k] for k in sorted(found))
        raise DataError(
            f"{t.path}: the data has joint columns {have}, but robot {robot.name} has {n} "
            f"joints (expected j1_deg .. j{n}_deg)."
        )
    cols = [found[k] for k in range(1, n + 1)]
    q = np.empty((len(t), n))
    for k, c in enumerate(cols):
        unit = c.rsplit("_", 1)[1]
        prismatic = robot.joints[k].kind == "prismatic"
        if prismatic and unit not in ("mm", "m"):
            raise DataError(
                f"{t.path}: column '{c}': joint {k + 1} is prismatic; use j{k + 1}_mm."
            )
        if not prismatic and unit not in ("deg", "rad"):
            raise DataError(
                f"{t.path}: column '{c}': joint {k + 1} is revolute; use j{k + 1}_deg."
            )
        q[:, k] = t.numbers(c) / _TO_FILE[unit]
    deg_cols = [k for k, c in enumerate(cols) if c.endswith("_deg")]
    if deg_cols and len(t) >= 5:
        vals = np.degrees(q[:, deg_cols])
        spread = vals.max(axis=0) - vals.min(axis=0)
        if np.abs(vals).max() <= 2 * np.pi + 1e-9 and spread.max() > 0.05:
            raise DataError(
                f"{t.path}: columns {cols[deg_cols[0]]}..{cols[deg_cols[-1]]}: every value is "
                f"within ±{2 * np.pi:.2f}, which looks like radians; convert to degrees or "
                "name the columns jK_rad."
            )
    return cols, q, _limits(t, robot, cols, q, allow_out_of_limits)


def _check_columns(t: Table, joint_cols: list[str], n_joints: int) -> list[Diagnostic]:
    """Refuse a column name that is near a known one (a typo, a plural, another case) or
    lacks its unit; other extra columns are allowed (and ignored): one that names set-ups
    with a finding (:func:`_set_like`)."""
    found: list[Diagnostic] = []
    for c in t.header:
        if c in _KNOWN or c in joint_cols:
            continue
        low = c.strip().lower()
        m = _JOINT_RE.match(low)
        if m and int(m.group(1)) <= n_joints:
            guess: str | None = low
        else:
            guess = near_miss(c, _KNOWN)
        if guess is not None:
            raise DataError(
                f"{t.path}: column {c!r} is not understood; did you mean {guess!r}? "
                "(Rename it; an extra column must not look like a known one.)"
            )
        base = low.split("_")[0]
        if base in _UNITLESS or low in _UNITLESS or m:
            raise DataError(
                f"{t.path}: column {c!r} is not understood; column names carry their "
                "unit (x_mm, sigma_mm, payload_kg, j1_deg, ...)."
            )
        if base in _SET_LIKE and "set" not in t.header:
            found += _set_like(t, c)
    return found


# Names a user may give the column of set-ups (sessions, tracker stations): read under
# another name, several set-ups would be calibrated with one user frame, unsaid.
_SET_LIKE = frozenset(
    {"set", "session", "sessions", "station", "stations", "setup", "setups"}
)


def _set_like(t: Table, c: str) -> list[Diagnostic]:
    """A finding for a column ``c`` that names set-ups with several values, where the
    data have no ``set`` column (one value throughout is a label). A warning, not an
    error: such a column may be meant for ``--cv-groups`` (poses of one set-up)."""
    values = sorted({v.strip() for v in t.column(c)})
    if len(values) < 2:
        return []
    shown = ", ".join(repr(v) for v in values[:4]) + (" ..." if len(values) > 4 else "")
    return [
        Diagnostic(
            "set_like_column",
            f"{t.path}: column {c!r} has {len(values)} values ({shown}), but kinecal "
            "reads set-ups (sessions, tracker stations: one user frame each) from a "
            "column named 'set' only: every row is taken in one user frame. Rename it "
            "to 'set' if the rows are of several set-ups (or name it in --cv-groups).",
            stage="data",
        )
    ]


def _kind(t: Table) -> tuple[str, Sequence[str]]:
    if "target" in t.header or "xc_mm" in t.header:
        return "sensor", _SENSOR
    if any(c in t.header for c in _QUAT):
        if any(c in t.header for c in _WPR):
            raise DataError(
                f"{t.path}: give the orientation either as qw..qz or as w_deg, p_deg, "
                "r_deg, not both."
            )
        return "pose", (*_POINT, *_QUAT)
    if any(c in t.header for c in _WPR):
        return "pose", (*_POINT, *_WPR)
    return "point", _POINT


# Positions beyond 1 km from the instrument's origin are typing errors, not data (and
# their squares overflow in the solvers: a cell of 1e300 hung the calibration).
MAX_POSITION_MM = 1e6


# The largest plausible value of the optional columns: beyond it a cell is a typing
# error (a payload of 1e300 kg overflowed the compliance terms).
_MAX_OPTIONAL = {"sigma_mm": MAX_POSITION_MM, "sigma_deg": 360.0, "payload_kg": 1e5}
_POSITIVE = {
    "payload_kg": "a mass in kg, 0 or more (the payload at the tool beyond the tool "
    "itself; 0: no payload)",
    "sigma_mm": "a positive standard deviation in mm",
    "sigma_deg": "a positive standard deviation in deg",
}


def _check_far(t: Table, xyz_mm: np.ndarray, cols: Sequence[str]) -> None:
    """Refuse a row whose position (mm) is beyond :data:`MAX_POSITION_MM`."""
    far = np.flatnonzero(np.abs(xyz_mm).max(axis=1) > MAX_POSITION_MM)
    if far.size:
        i = int(far[0])
        v = xyz_mm[i]
        raise DataError(
            f"{t.path}: line {t.lines[i]}, columns {', '.join(cols)}: ({v[0]:.6g}, "
            f"{v[1]:.6g}, {v[2]:.6g}) mm; expected positions within "
            f"{MAX_POSITION_MM:.0e} mm of the origin (a typing error?)."
        )


def _looks_like_metres(t: Table, xyz: np.ndarray, cols: Sequence[str]) -> None:
    _check_far(t, xyz, cols)
    if len(t) >= 5 and np.abs(xyz).max() < 5.0 and np.ptp(xyz, axis=0).max() > 1e-3:
        raise DataError(
            f"{t.path}: columns {', '.join(cols)}: every value is below 5, which looks "
            "like metres; convert to millimetres."
        )


# A row's sigma below this fraction of the median of the others gives it a weight
# 1e6 x theirs: it decides the fit alone (one row at 1e-12 mm among 0.01 mm ones
# gave 2.5 mm held-out errors). Such a row is refused.
_MIN_SIGMA_RATIO = 1e-3


def _check_weights(t: Table, col: str, v: np.ndarray) -> None:
    """Per-row sigmas against the robust spread of the others (their median)."""
    if v.size < 3:
        return
    med = median(v)  # (np.median would import numpy.ma: 20 ms of a command)
    low = np.flatnonzero(v < _MIN_SIGMA_RATIO * med)
    if low.size:
        i = int(low[0])
        raise DataError(
            f"{t.path}: line {t.lines[i]}, column '{col}': {v[i]:.6g}, "
            f"{v[i] / med:.2g} of the median {med:.6g} of the rows ({low.size} row"
            f"{'s' if low.size > 1 else ''} so small): such a row outweighs the others "
            f"{(med / v[i]) ** 2:.2g} times and decides the fit alone; expected at "
            f"least {_MIN_SIGMA_RATIO * med:.6g} (a typing error, or units?)."
        )


def _unit_quaternions(t: Table) -> np.ndarray:
    quat = np.column_stack([t.numbers(c) for c in _QUAT])
    nrm = np.linalg.norm(quat, axis=1)
    bad = np.flatnonzero(np.abs(nrm - 1.0) > 0.01)
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{t.path}: line {t.lines[i]}, columns qw..qz: quaternion norm {nrm[i]:.4f}; "
            "expected a unit quaternion (w first)."
        )
    return quat


def _optional_columns(t: Table) -> dict[str, np.ndarray | None]:
    """``sigma``, ``sigma_rot`` and ``payload_kg`` of the rows (SI; None without the
    column), each cell checked: positive, and below its typing-error bound."""
    optional = {
        "sigma": ("sigma_mm", 1e-3),
        "sigma_rot": ("sigma_deg", np.pi / 180.0),
        "payload_kg": ("payload_kg", 1.0),
    }
    out: dict[str, np.ndarray | None] = {}
    for name, (col, scale) in optional.items():
        if col not in t.header:
            out[name] = None
            continue
        v = t.numbers(col)
        low = v < 0 if col == "payload_kg" else v <= 0
        if np.any(low):
            i = int(np.flatnonzero(low)[0])
            raise DataError(
                f"{t.path}: line {t.lines[i]}, column '{col}': {v[i]:.6g}; expected "
                + _POSITIVE.get(col, "a positive value")
                + "."
            )
        high = _MAX_OPTIONAL[col]
        if np.any(v > high):
            i = int(np.flatnonzero(v > high)[0])
            raise DataError(
                f"{t.path}: line {t.lines[i]}, column '{col}': {v[i]:.6g}; expected a "
                f"value up to {high:.6g} (a typing error?)."
            )
        if name != "payload_kg":
            _check_weights(t, col, v)
        out[name] = v * scale
    return out


def _read(
    path: str | Path,
    robot: RobotDescription,
    targets: str | Path | Targets | None,
    allow_out_of_limits: bool,
) -> tuple[Measurements, list[Diagnostic], bool]:
    """The measurements, the out-of-limits finding, and whether the orientations came
    from quaternion columns."""
    expect_type(robot, RobotDescription, "robot", "kinecal.robot.load_robot")
    t = read_table(path)
    named = _check_columns(
        t, [c for c in t.header if _JOINT_RE.match(c)], robot.n_joints
    )
    _, q, limits = _joint_columns(t, robot, allow_out_of_limits)
    kind, need = _kind(t)
    for c in need:
        if c not in t.header:
            raise DataError(
                f"{t.path}: missing column '{c}' ({kind} data needs {', '.join(need)})."
            )
    set_index, set_labels = _labels(t, "set")
    marker_index, marker_labels = _labels(t, "marker")
    common: dict[str, object] = {
        "set_index": set_index,
        "set_labels": set_labels,
        "marker_index": marker_index,
        "marker_labels": marker_labels,
        "rows": t.lines.copy(),
        "source": t.path,
        **_optional_columns(t),
    }
    found = named + ([] if limits is None else [limits])
    if kind != "sensor" and targets is not None:
        what = "" if isinstance(targets, Targets) else f" {targets}"
        raise DataError(
            f"{t.path}: {kind} data (x_mm, y_mm, z_mm{'...' if kind == 'pose' else ''})"
            f" measures the tool directly; the targets file{what} is for sensor data "
            "(target, xc_mm, yc_mm, zc_mm): expected no --targets with this file."
        )
    if kind == "sensor":
        if targets is None:
            raise DataError(
                f"{t.path}: sensor data (target, xc_mm, ...) needs a --targets file."
            )
        tg = targets if isinstance(targets, Targets) else read_targets(targets)
        tnames = [s.strip() for s in t.column("target")]
        index = {lab: i for i, lab in enumerate(tg.labels)}
        missing = [i for i, lab in enumerate(tnames) if lab not in index]
        if missing:
            raise DataError(
                f"{t.path}: line {t.lines[missing[0]]}, column 'target': "
                f"{tnames[missing[0]]!r} is not in the targets file ({', '.join(tg.labels)})."
            )
        pc = np.column_stack([t.numbers(c) for c in _SENSOR[1:]])
        _looks_like_metres(t, pc, _SENSOR[1:])
        meas = Measurements(
            "sensor",
            q,
            mm_to_m(pc),
            target_index=np.fromiter((index[s] for s in tnames), np.intp, len(t)),
            targets=tg.p,
            target_labels=tg.labels,
            **common,  # type: ignore[arg-type]
        )
        return meas, found, False
    xyz = np.column_stack([t.numbers(c) for c in _POINT])
    _looks_like_metres(t, xyz, _POINT)
    R = None
    if kind == "pose" and "w_deg" in t.header:
        R = wpr_to_matrix(deg_to_rad(np.column_stack([t.numbers(c) for c in _WPR])))
    elif kind == "pose":
        R = quat_wxyz_to_matrix(_unit_quaternions(t))
    meas = Measurements(kind, q, mm_to_m(xyz), R_user_cam=R, **common)  # type: ignore[arg-type]
    frozen_orientations(meas, robot, ", ".join(_WPR if "w_deg" in t.header else _QUAT))
    return meas, found, R is not None and "qw" in t.header


def read_data(
    path: str | Path,
    robot: RobotDescription,
    targets: str | Path | Targets | None = None,
    *,
    allow_out_of_limits: bool = False,
) -> tuple[Measurements, list[Diagnostic]]:
    """Read a measurement CSV and check it: the measurements and the findings that do
    not stop the run (:class:`~kinecal.identification.Diagnostic`, stage ``'data'``:
    accepted out-of-limit rows, duplicated rows, payload beyond the rating, quaternion
    order, poor excitation; see :mod:`kinecal.io._checks`).

    Raises
    ------
    DataError
        As :func:`read_measurements`.
    """
    meas, found, quaternions = _read(path, robot, targets, allow_out_of_limits)
    return meas, found + data_diagnostics(meas, robot, quaternions=quaternions)


def read_measurements(
    path: str | Path,
    robot: RobotDescription,
    targets: str | Path | Targets | None = None,
    *,
    allow_out_of_limits: bool = False,
    check: bool = True,
) -> Measurements:
    """Read and validate a measurement CSV for ``robot`` (see the module docstring).

    Findings that do not stop the run are issued as :class:`DataWarning` (``check=False``
    skips the checks of :func:`~kinecal.io.data_diagnostics`).

    Raises
    ------
    DataError
        Missing column, unparsable or non-finite value, units that look wrong, joint count
        that does not match the robot, a joint value beyond the limits (unless
        ``allow_out_of_limits``), a column name near a known one, unknown target, empty
        file.
    """
    if check:
        meas, found = read_data(
            path, robot, targets, allow_out_of_limits=allow_out_of_limits
        )
    else:
        meas, found, _ = _read(path, robot, targets, allow_out_of_limits)
    for d in found:
        warnings.warn(DataWarning(d.message, d), stacklevel=2)
    return meas


def _payload(t: Table, robot: RobotDescription) -> np.ndarray:
    """The ``payload_kg`` column [kg]: finite, >= 0, and at most 10 x the robot's
    rated payload (a model file cannot hold more; a unit mistake: g, lb)."""
    from kinecal.io._model_bounds import payload_limit

    v = t.numbers("payload_kg")
    hi, also = payload_limit(robot)
    bad = np.flatnonzero(~((v >= 0) & (v <= hi)))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{t.path}: line {t.lines[i]}, column 'payload_kg': {v[i]:.6g}; expected "
            f"0 to {hi:.6g} kg{also}: a unit mistake (g, lb)?"
        )
    return v
