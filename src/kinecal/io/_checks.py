"""Checks of measurement data before any fit: mistakes a metrology engineer meets weekly.

Each finding is a :class:`~kinecal.identification.Diagnostic` (stage ``'data'``) with a
stable code, the file lines concerned and a message, so the command line prints it and the
calibration report keeps it:

* ``duplicate_rows``: rows that repeat an earlier row exactly (they count twice and shrink
  the reported standard deviations);
* ``payload_over_rating``: a payload above the robot's rated payload;
* ``quaternion_order``: orientations that agree with the robot only when the quaternion is
  read in x, y, z, w order (or conjugated). The angle of the rotation between two poses
  does not depend on the unknown user and tool frames, so it is compared with the nominal
  robot's without any fit: ``angle(R_i^T R_j) = angle(F_i^T F_j)``, ``F`` the flange
  orientation of the nominal kinematics;
* ``poor_excitation``: a joint that hardly moves, or a tool orientation that hardly
  changes, so some parameters cannot be separated from others;
* ``lone_label``: a marker or set seen in one row only (a calibration fits its offset or
  frame to that row alone: nothing checks it);
* ``positions_only`` and refusals when data and model are of different kinds
  (:func:`check_data_for_model`).

See docs/real-data-checklist.md.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

import numpy as np

from kinecal._stats import median, present
from kinecal.errors import DataError
from kinecal.geometry import matrix_to_quat_wxyz, quat_wxyz_to_matrix, so3_log
from kinecal.measurement import CalibratedModel, Diagnostic, Measurements
from kinecal.robot import RobotDescription

__all__ = [
    "DataWarning",
    "check_data_for_model",
    "data_diagnostics",
    "extrapolation",
    "lone_labels",
    "near_miss",
]

# A joint that moves less than this over the data hardly excites its parameters.
STILL_DEG, STILL_MM = 5.0, 5.0
# Tool orientations all within this angle of the first: the tool offset is not separable.
SAME_ORIENTATION_DEG = 5.0
# Quaternion order: the order as read is suspect when the median mismatch of pose-to-pose
# rotation angles exceeds this, and another reading fits at least 4x better.
ORDER_MISMATCH_DEG = 3.0
ORDER_FACTOR = 4.0
# Pose pairs of the quaternion check and poses of the orientation spread: a sample is
# enough for a median and a spread, and keeps a million-row file fast.
_MAX_PAIRS = 2_000
# Rows the excitation check turns through the forward kinematics first.
_FEW_ROWS = 32
_STAGE = "data"


class DataWarning(UserWarning):
    """A finding about the data; ``.diagnostic`` holds the structured record (the
    warning's only argument is the message, so it pickles and re-creates as usual)."""

    def __init__(self, message: str, diagnostic: Diagnostic | None = None) -> None:
        super().__init__(message)
        self.diagnostic = diagnostic


def _lines(meas: Measurements, idx: Iterable[int], limit: int = 8) -> str:
    rows = [int(meas.rows[i]) for i in idx]
    text = ", ".join(str(r) for r in rows[:limit])
    return text + (f" and {len(rows) - limit} more" if len(rows) > limit else "")


def duplicate_rows(meas: Measurements) -> Diagnostic | None:
    """Rows whose joints, measurement, set, marker (and target) equal an earlier row's."""
    parts = [meas.q_ctrl, meas.p, meas.set_index[:, None], meas.marker_index[:, None]]
    if meas.R_user_cam is not None:
        parts.append(meas.R_user_cam.reshape(meas.n, 9))
    if meas.target_index is not None:
        parts.append(meas.target_index[:, None])
    key = np.column_stack([np.asarray(p, dtype=np.float64) for p in parts])
    # Equal rows have equal fingerprints (the same arithmetic on the same numbers); a
    # stable sort puts them next to each other, earliest first, and the rows themselves
    # are compared. (np.unique on rows is ten times slower.)
    # Irrational weights in [1, 2) (the golden ratio's multiples, mod 1): no two columns
    # alike, no random generator (numpy.random costs 10 ms to import).
    weights = 1.0 + np.modf(np.arange(1, key.shape[1] + 1) * 0.6180339887498949)[0]
    fingerprint = np.zeros(meas.n)
    for j in range(key.shape[1]):  # element-wise: BLAS rounding may depend on the row
        fingerprint += key[:, j] * weights[j]
    order = np.argsort(fingerprint, kind="stable")
    k = key[order]
    same = (fingerprint[order][1:] == fingerprint[order][:-1]) & np.all(
        k[1:] == k[:-1], axis=1
    )
    dup = np.sort(order[1:][same])
    if not dup.size:
        return None
    return Diagnostic(
        "duplicate_rows",
        f"{meas.source}: {dup.size} rows repeat an earlier row exactly (lines "
        f"{_lines(meas, dup)}): each copy counts as a new measurement and makes the "
        "reported standard deviations too small; remove the copies.",
        rows=tuple(int(meas.rows[i]) for i in dup),
        stage=_STAGE,
    )


def lone_labels(
    meas: Measurements, kinds: tuple[str, ...] = ("marker", "set")
) -> list[Diagnostic]:
    """Markers and sets (``kinds``; of data with several) seen in one row only: a
    calibration fits that marker's offset (that set's frame) to the one row, which it
    then matches exactly, so nothing checks it."""
    out = []
    for what, idx, labels, fitted in (
        ("marker", meas.marker_index, meas.marker_labels, "its offset on the tool"),
        ("set", meas.set_index, meas.set_labels, "its user frame"),
    ):
        if what not in kinds:
            continue
        counts = np.bincount(idx, minlength=len(labels))
        if (counts > 0).sum() < 2:
            continue
        for k in np.flatnonzero(counts == 1):
            row = int(meas.rows[int(np.flatnonzero(idx == k)[0])])
            out.append(
                Diagnostic(
                    "lone_label",
                    f"{meas.source}: {what} {labels[k]!r} is seen in one row only "
                    f"(line {row}): a calibration fits {fitted} to that row alone, so "
                    f"nothing checks it; measure it at several poses or remove the row.",
                    rows=(row,),
                    stage=_STAGE,
                )
            )
    return out


def payload_over_rating(
    meas: Measurements, robot: RobotDescription
) -> Diagnostic | None:
    """A payload (per row, or the robot file's) above the robot's rated payload."""
    rated = robot.rated_payload_kg
    if rated is None:
        return None
    if meas.payload_kg is not None:
        over = np.flatnonzero(meas.payload_kg > rated * (1 + 1e-9))
        if over.size:
            return Diagnostic(
                "payload_over_rating",
                f"{meas.source}: payload_kg up to {float(meas.payload_kg.max()):g} kg "
                f"(lines {_lines(meas, over)}), above the {rated:g} kg rated payload of "
                f"{robot.name}: a unit mistake (g, lb)? Beyond its rating the arm bends "
                "more than the linear compliance model describes.",
                rows=tuple(int(meas.rows[i]) for i in over),
                stage=_STAGE,
            )
    if robot.payload_kg is not None and robot.payload_kg > rated * (1 + 1e-9):
        return Diagnostic(
            "payload_over_rating",
            f"{robot.source}: payload_kg {robot.payload_kg:g} kg is above the "
            f"{rated:g} kg rated payload of {robot.name}.",
            stage=_STAGE,
        )
    return None


def _pairs(meas: Measurements) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of rows with the same set and marker: neighbours and half a group apart."""
    group = meas.set_index * len(meas.marker_labels) + meas.marker_index
    a_all, b_all = [], []
    for g in present(group):
        idx = np.flatnonzero(group == g)
        for step in {1, max(len(idx) // 2, 1)}:
            a_all.append(idx[:-step])
            b_all.append(idx[step:])
    a, b = np.concatenate(a_all), np.concatenate(b_all)
    if a.size > _MAX_PAIRS:
        keep = np.linspace(0, a.size - 1, _MAX_PAIRS).astype(np.intp)  # evenly spread
        a, b = a[keep], b[keep]
    return a, b


def _relative_angle(R: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of ``R_a^T R_b`` [rad]: trace through the element-wise product."""
    c = (np.einsum("nij,nij->n", R[a], R[b]) - 1.0) / 2.0
    return np.arccos(np.clip(c, -1.0, 1.0))


def _mismatch_deg(R: np.ndarray, F: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    """Median misfit [deg] of the pose-to-pose rotations ``R_a^T R_b`` (rotation vectors,
    tool frame) to the nominal ones ``F_a^T F_b`` turned by the best single rotation."""
    w_meas = so3_log(np.einsum("nji,njk->nik", R[a], R[b]))
    w_nom = so3_log(np.einsum("nji,njk->nik", F[a], F[b]))
    U, _, Vt = np.linalg.svd(w_nom.T @ w_meas)  # Kabsch without translation
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0])
    Q = Vt.T @ D @ U.T  # w_meas ~ Q w_nom
    return float(np.degrees(median(np.linalg.norm(w_meas - w_nom @ Q.T, axis=1))))


def quaternion_order(meas: Measurements, robot: RobotDescription) -> Diagnostic | None:
    """Orientations that agree with the robot only in x, y, z, w order (or inverted).

    In the tool frame, the rotation from pose a to pose b is the nominal robot's
    ``F_a^T F_b`` seen through the unknown but fixed tool orientation:
    ``R_a^T R_b = Q F_a^T F_b Q^T`` whatever the user frame. Its rotation vectors are
    those of the robot turned by ``Q``, found in closed form (Kabsch); the median misfit
    is small for the right reading and tens of degrees for a wrong one. (The angle alone
    would not tell: it is the same for any order of the quaternion's components.) Read in
    x, y, z, w order, a quaternion gives ``A R^T B`` for fixed ``A``, ``B`` (an odd
    permutation of the components is a reflection of the quaternion), so the two mistakes
    are one for a calibration that fits the frames.
    """
    if meas.R_user_cam is None or meas.n < 4:
        return None
    a, b = _pairs(meas)
    if a.size < 3:
        return None
    used = present(np.concatenate([a, b]))
    inv = np.searchsorted(used, np.concatenate([a, b]))
    a, b = inv[: a.size], inv[a.size :]  # into the rows used
    F = robot.fk_flange(meas.q_ctrl[used])[:, :3, :3]
    R = meas.R_user_cam[used]
    read = _mismatch_deg(R, F, a, b)
    quat = matrix_to_quat_wxyz(R)
    other = _mismatch_deg(quat_wxyz_to_matrix(quat[:, [3, 0, 1, 2]]), F, a, b)
    if read < ORDER_MISMATCH_DEG or other * ORDER_FACTOR > read:
        return None
    return Diagnostic(
        "quaternion_order",
        f"{meas.source}: the rotations between poses differ from the robot's by "
        f"{read:.1f} deg (median) as written, by {other:.2f} deg with the quaternions "
        "read in x, y, z, w order (or as the inverse rotations: the same up to the "
        "frames): put w first in qw..qz, and give the tool's orientation in the user "
        "frame, not the inverse.",
        stage=_STAGE,
    )


def _orientation_spread_deg(
    meas: Measurements, robot: RobotDescription, first: int | None = None
) -> float:
    """Largest angle of a nominal flange orientation from the first row's [deg]; on a
    sample of the rows first (the forward kinematics of a million rows takes a lot of
    memory), all rows only when the sample stays within the limit. With ``first``, on
    that many rows before (a lower bound: whether the spread reaches the limit is often
    clear from a few rows, 2.5 ms less of a 2000-row check, issue 36)."""
    n = meas.n
    rows = np.linspace(0, n - 1, min(n, _MAX_PAIRS)).astype(np.intp)  # sorted
    rows = rows[np.r_[True, np.diff(rows) > 0]]  # (np.unique imports numpy.ma)
    tries: tuple[np.ndarray | None, ...] = (rows, None) if rows.size < n else (rows,)
    if first is not None and first < rows.size:
        tries = (rows[np.linspace(0, rows.size - 1, first).astype(np.intp)], *tries)
    for idx in tries:
        sel = np.arange(n) if idx is None else idx
        spread = 0.0
        for a in range(0, sel.size, _MAX_PAIRS):
            part = np.concatenate([[0], sel[a : a + _MAX_PAIRS]])
            F = robot.fk_flange(meas.q_ctrl[part])[:, :3, :3]
            zero = np.zeros(part.size, np.intp)
            ang = _relative_angle(F, zero, np.arange(part.size))
            spread = max(spread, float(np.degrees(ang.max())))
        if spread >= SAME_ORIENTATION_DEG:
            break
    return spread


def frozen_orientations(
    meas: Measurements, robot: RobotDescription, columns: str
) -> None:
    """Refuse pose data whose measured orientations stay put while the robot turns the
    tool: the angle between two poses' tool orientations is the same in any user frame
    and tool, so a real measurement turns as the flange does. A constant orientation
    (a placeholder 1, 0, 0, 0, or the instrument's own frame) cannot be fitted (the
    tool rotation is undetermined)."""
    R = meas.R_user_cam
    if meas.kind != "pose" or R is None or meas.n < 2:
        return
    zero = np.zeros(meas.n, np.intp)
    measured = float(np.degrees(_relative_angle(R, zero, np.arange(meas.n)).max()))
    if measured >= SAME_ORIENTATION_DEG / 10:
        return
    turned = _orientation_spread_deg(meas, robot)
    if turned < SAME_ORIENTATION_DEG:
        return
    raise DataError(
        f"{meas.source}: columns {columns}: every row's orientation lies within "
        f"{measured:.3g} deg of the first, but the robot turns the tool by up to "
        f"{turned:.3g} deg between these poses; expected the tool's measured "
        "orientation per row (or no orientation columns, for position data)."
    )


def excitation(meas: Measurements, robot: RobotDescription) -> list[Diagnostic]:
    """Joints that hardly move and a tool orientation that hardly changes."""
    out = []
    span = np.ptp(meas.q_ctrl, axis=0)
    still = []
    for k, j in enumerate(robot.joints):
        prismatic = j.kind == "prismatic"
        size = span[k] * (1e3 if prismatic else 180.0 / np.pi)
        if meas.n >= 2 and size < (STILL_MM if prismatic else STILL_DEG):
            still.append(f"J{k + 1} {size:.3g} {'mm' if prismatic else 'deg'}")
    if still:
        names = ", ".join(s.split()[0] for s in still)
        out.append(
            Diagnostic(
                "poor_excitation",
                f"{meas.source}: {names} hardly "
                f"{'moves' if len(still) == 1 else 'move'} (range {', '.join(still)} "
                f"over {meas.n} rows): the parameters of "
                f"{'that joint' if len(still) == 1 else 'those joints'} (offset, link "
                "lengths, transmission terms) cannot be separated from the frames and "
                "from each other; spread each joint over its range (at least 30 deg, "
                "better 90 deg or more).",
                stage=_STAGE,
            )
        )
    if meas.n >= 2:  # (its value is said only below the limit: all rows then)
        spread = _orientation_spread_deg(meas, robot, first=_FEW_ROWS)
        if spread < SAME_ORIENTATION_DEG:
            out.append(
                Diagnostic(
                    "poor_excitation",
                    f"{meas.source}: the tool orientation hardly changes (all poses "
                    f"within {spread:.3g} deg of the first): the tool offset cannot be "
                    "separated from the user frame; measure at several tool "
                    "orientations (30 deg apart or more).",
                    stage=_STAGE,
                )
            )
    return out


def set_units(meas: Measurements, robot: RobotDescription) -> None:
    """Refuse a set (one session of several) whose positions look like metres or whose
    joint values look like radians while the other sets' do not: the file-wide unit
    checks took the mix as plausible, and the calibration failed on a parameter far
    off ('are these measurements of another robot?') without naming the set."""
    if len(meas.set_labels) < 2:
        return
    rev = ~np.asarray(robot.prismatic)
    p_mm = np.abs(meas.p).max(axis=1) * 1e3
    q_deg = np.degrees(np.abs(meas.q_ctrl[:, rev])).max(axis=1) if rev.any() else None
    cols = "xc_mm, yc_mm, zc_mm" if meas.kind == "sensor" else "x_mm, y_mm, z_mm"
    for s, label in enumerate(meas.set_labels):
        rows = meas.set_index == s
        if rows.sum() < 3 or rows.all():
            continue
        first = int(np.asarray(meas.rows)[rows][0])
        where = f"{meas.source}: set {label!r} (from line {first})"
        if p_mm[rows].max() < 5.0 <= p_mm[~rows].max():
            raise DataError(
                f"{where}: columns {cols}: every value of its {int(rows.sum())} rows is "
                "below 5, which looks like metres (the other sets' are not); convert "
                "that set to millimetres."
            )
        limit = 2 * np.pi + 1e-9
        if q_deg is not None and q_deg[rows].max() <= limit < q_deg[~rows].max():
            raise DataError(
                f"{where}: every joint value of its {int(rows.sum())} rows is within "
                f"±{2 * np.pi:.2f} deg, which looks like radians (the other sets' are "
                "not); convert that set to degrees."
            )


def data_diagnostics(
    meas: Measurements, robot: RobotDescription, *, quaternions: bool = True
) -> list[Diagnostic]:
    """Every data check of this module on ``meas`` (warnings, never errors).

    Parameters
    ----------
    meas : Measurements
    robot : RobotDescription, the nominal robot the data are for.
    quaternions : bool
        The orientations were read from quaternion columns (the order check applies).
    """
    out: list[Diagnostic] = []
    for d in (
        duplicate_rows(meas),
        payload_over_rating(meas, robot),
        quaternion_order(meas, robot) if quaternions else None,
    ):
        if d is not None:
            out.append(d)
    return out + excitation(meas, robot)


def check_data_for_model(
    meas: Measurements, cal: CalibratedModel
) -> tuple[Measurements, list[Diagnostic]]:
    """The data as the calibrated model can evaluate them, and what is left out.

    Pose data for a model without tool orientation (calibrated on tracker points) keep
    their positions only (``positions_only``); the other kinds must match.

    Raises
    ------
    DataError
        Sensor data (a target seen in the cam frame) for a model calibrated on tracker
        points or poses, or tracker data for a sensor model: the two map different
        quantities, the errors would be meaningless (metres).
    """
    kind = cal.info.get("kind")
    if kind not in ("point", "pose", "sensor"):
        kind = "pose" if cal.model.spec.cam_rotation else "point"
    what = {
        "point": "tracker points (x_mm, y_mm, z_mm)",
        "pose": "poses (x_mm .. qz)",
        "sensor": "sensor data (target, xc_mm, yc_mm, zc_mm)",
    }
    if meas.kind == kind or {meas.kind, kind} == {"point", "pose"}:
        outside = extrapolation(cal, meas.q_ctrl, meas.rows, meas.source)
        found = [] if outside is None else [outside]
        if meas.kind == "pose" and not cal.model.spec.cam_rotation:
            note = Diagnostic(
                "positions_only",
                f"{meas.source}: pose data, but the model was calibrated on "
                f"{what[str(kind)]} and has no tool orientation: only the positions "
                "are compared.",
                stage=_STAGE,
            )
            meas = replace(meas, kind="point", R_user_cam=None, sigma_rot=None)
            return meas, [note, *found]
        return meas, found
    if meas.kind == "sensor" and not cal.model.spec.cam_rotation:
        why = "the model has no sensor orientation to map the measured points"
    elif meas.kind == "sensor":
        why = "its cam frame is the tracked tool, not a sensor"
    else:
        why = "a sensor model maps points measured in the sensor frame"
    raise DataError(
        f"{meas.source}: {what[meas.kind]}, but the model was calibrated on "
        f"{what[str(kind)]}: {why}; evaluate it on data of the same kind."
    )


# A joint value this far outside the calibrated range (a fraction of its span, at least
# 1 deg or 1 mm) is an extrapolation.
_RANGE_SLACK = 0.02


def extrapolation(
    cal: CalibratedModel,
    q_ctrl: np.ndarray,
    rows: Iterable[int],
    source: str,
    what: str = "poses",
    labels: Sequence[str] | None = None,
) -> Diagnostic | None:
    """``extrapolation``: rows whose joint values lie outside the joint ranges the model
    was calibrated on (its file's ``info: calibrated_joint_range``); the model's
    prediction there is an extrapolation and can be far off. None when every row is
    inside, or the model file does not say its ranges. ``labels``: how to name each
    row (a program's ``line 12 (P[3])``; default ``line N (row K)``: ``rows``
    are file lines, K counts the data rows from 1)."""
    robot = cal.model.robot
    got = cal.info.get("calibrated_joint_range")
    n = robot.n_joints
    try:
        rng = np.asarray(got, dtype=float)
    except (TypeError, ValueError):
        return None
    if got is None or rng.shape != (n, 2) or not np.all(np.isfinite(rng)):
        return None
    scale = np.where(robot.prismatic, 1e3, 180.0 / np.pi)
    q = np.asarray(q_ctrl, float) * scale
    slack = np.maximum(_RANGE_SLACK * (rng[:, 1] - rng[:, 0]), 1.0)
    # A revolute joint without limits (a URDF's continuous joint) turns on: every term
    # of the model repeats each turn, so an angle a whole number of turns from the
    # calibrated range is inside it.
    turns = ~robot.prismatic & ~np.isfinite(robot.limits).all(axis=1)
    qc = np.where(turns, rng[:, 0] - slack + (q - rng[:, 0] + slack) % 360.0, q)
    low, high = qc < rng[:, 0] - slack, qc > rng[:, 1] + slack
    out = low | high
    bad = np.flatnonzero(out.any(axis=1))
    if bad.size == 0:
        return None
    row_of = list(rows)
    names = robot.joint_names
    unit = ["mm" if p else "deg" for p in robot.prismatic]
    parts = []
    for i in bad[:8]:
        j = int(np.flatnonzero(out[i])[0])
        # the data's column too where the robot names its joints otherwise (UR, URDF)
        col = "" if names[j] == f"J{j + 1}" else f" (j{j + 1}_{unit[j]})"
        # the file line, and the data row for a user counting rows (a data frame's)
        where = labels[i] if labels is not None else f"line {row_of[i]} (row {i + 1})"
        parts.append(
            f"{where} {names[j]}{col} {q[i, j]:.1f} {unit[j]} (calibrated "
            f"{rng[j, 0]:.1f} .. {rng[j, 1]:.1f})"
        )
    more = f" and {bad.size - 8} more" if bad.size > 8 else ""
    joints = sorted({names[j] for j in np.flatnonzero(out.any(axis=0))})
    return Diagnostic(
        "extrapolation",
        f"{source}: {bad.size} of {q.shape[0]} {what} lie outside the joint ranges the "
        f"model was calibrated on ({', '.join(joints)}): {'; '.join(parts)}{more}. Its "
        "predictions there extrapolate and can be far off; calibrate with poses that "
        "cover them.",
        parameters=tuple(joints),
        rows=tuple(int(row_of[i]) for i in bad),
        stage=_STAGE,
    )


def _distance(a: str, b: str) -> int:
    """Optimal string alignment distance (edits, adjacent swaps count one)."""
    d = [
        [i + j if i * j == 0 else 0 for j in range(len(b) + 1)]
        for i in range(len(a) + 1)
    ]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            cost = a[i - 1] != b[j - 1]
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + cost)
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


def near_miss(name: str, known: Iterable[str]) -> str | None:
    """The known column ``name`` was probably meant to be, or None.

    Near: the same up to case, spaces and dashes, or a plural or singular ``s``; or one
    edit away from a name of 5 or more letters, two from one of 8 or more.
    """
    norm = name.strip().lower().replace("-", "_").replace(" ", "_")
    best: tuple[int, str] | None = None
    for k in sorted(known):
        if norm in (k, k + "s", k + "es"):
            return k
        limit = 2 if len(k) >= 8 else 1 if len(k) >= 5 else 0
        dist = _distance(norm, k) if limit else limit + 1
        if dist <= limit and (best is None or dist < best[0]):
            best = (dist, k)
    return None if best is None else best[1]
