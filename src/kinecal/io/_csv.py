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

Every problem raises :class:`DataError` naming the file, the line and the column.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinecal.errors import DataError
from kinecal.geometry import quat_wxyz_to_matrix, wpr_to_matrix
from kinecal.identification import Measurements
from kinecal.robot import RobotDescription
from kinecal.units import deg_to_rad, mm_to_m

__all__ = [
    "CompensationTargets",
    "Table",
    "Targets",
    "read_compensation_targets",
    "read_measurements",
    "read_table",
    "read_targets",
]

_OPTIONAL = {"set", "marker", "payload_kg", "sigma_mm", "sigma_deg"}
_POINT = ("x_mm", "y_mm", "z_mm")
_QUAT = ("qw", "qx", "qy", "qz")
_WPR = ("w_deg", "p_deg", "r_deg")
_SENSOR = ("target", "xc_mm", "yc_mm", "zc_mm")
_JOINT_RE = re.compile(r"^j(\d+)_(deg|rad|mm|m)$")
# Columns a user might mean when they forget the unit suffix.
_UNITLESS = {"x", "y", "z", "xc", "yc", "zc", "sigma", "payload", "r"}


@dataclass(frozen=True)
class Table:
    """A CSV file as strings: header, rows and the file line of each row."""

    path: str
    header: list[str]
    rows: list[list[str]]
    lines: list[int]

    def column(self, name: str) -> list[str]:
        k = self.header.index(name)
        return [r[k] for r in self.rows]

    def numbers(self, name: str) -> np.ndarray:
        """Column as floats; any non-number or non-finite value is an error."""
        k = self.header.index(name)
        try:  # the whole column at once; cell by cell only to locate a bad value
            out = np.array([row[k] for row in self.rows], dtype=np.float64)
            if np.isfinite(out).all():
                return out
        except ValueError:
            pass
        out = np.empty(len(self.rows))
        for i, (row, line) in enumerate(zip(self.rows, self.lines)):
            s = row[k].strip()
            try:
                v = float(s)
            except ValueError:
                raise DataError(
                    f"{self.path}: line {line}, column '{name}': expected a number; got {s!r}."
                ) from None
            if not math.isfinite(v):
                raise DataError(
                    f"{self.path}: line {line}, column '{name}': expected a finite number; "
                    f"got {s!r}."
                )
            out[i] = v
        return out


def read_table(path: str | Path) -> Table:
    """Read a CSV file with a header; lines starting with '#' are comments."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"{p}: file not found.") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot read ({exc.strerror}).") from None
    except UnicodeDecodeError:
        raise DataError(f"{p}: not a text (UTF-8) CSV file.") from None
    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    for lineno, row in enumerate(csv.reader(text.splitlines()), start=1):
        if (
            not row
            or all(not c.strip() for c in row)
            or row[0].lstrip().startswith("#")
        ):
            continue
        if header is None:
            header = [c.strip() for c in row]
            dup = {c for c in header if header.count(c) > 1}
            if dup:
                raise DataError(
                    f"{p}: line {lineno}: duplicate column {sorted(dup)[0]!r}."
                )
            continue
        if len(row) != len(header):
            raise DataError(
                f"{p}: line {lineno}: {len(row)} values for {len(header)} columns."
            )
        rows.append(row)
        lines.append(lineno)
    if header is None:
        raise DataError(f"{p}: the file is empty (a header line is required).")
    if not rows:
        raise DataError(f"{p}: no data rows after the header.")
    return Table(str(p), header, rows, lines)


@dataclass(frozen=True)
class Targets:
    """Targets known in the user frame (sensor data)."""

    labels: tuple[str, ...]
    p: np.ndarray  # (K, 3) [m]
    radius: np.ndarray | None  # (K,) [m]


def read_targets(path: str | Path) -> Targets:
    """Read a targets file ``target, x_mm, y_mm, z_mm[, r_mm]``."""
    t = read_table(path)
    for c in ("target", "x_mm", "y_mm", "z_mm"):
        if c not in t.header:
            raise DataError(
                f"{t.path}: missing column '{c}' (need target, x_mm, y_mm, z_mm)."
            )
    labels = [s.strip() for s in t.column("target")]
    for lab, line in zip(labels, t.lines):
        if not lab:
            raise DataError(f"{t.path}: line {line}, column 'target': empty label.")
        if labels.count(lab) > 1:
            raise DataError(
                f"{t.path}: line {line}, column 'target': {lab!r} appears twice."
            )
    xyz = np.column_stack([t.numbers(c) for c in ("x_mm", "y_mm", "z_mm")])
    r = mm_to_m(t.numbers("r_mm")) if "r_mm" in t.header else None
    return Targets(tuple(labels), mm_to_m(xyz), r)


def _labels(t: Table, name: str) -> tuple[np.ndarray, tuple[str, ...]]:
    if name not in t.header:
        return np.zeros(len(t.rows), np.intp), ("",)
    vals = [s.strip() for s in t.column(name)]
    for v, line in zip(vals, t.lines):
        if not v:
            raise DataError(f"{t.path}: line {line}, column '{name}': empty label.")
    labels = tuple(dict.fromkeys(vals))
    index = {lab: i for i, lab in enumerate(labels)}
    return np.array([index[v] for v in vals], np.intp), labels


def _joint_columns(t: Table, robot: RobotDescription) -> tuple[list[str], np.ndarray]:
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
            f"{t.path}: no joint columns; expected j1_deg .. j{n}_deg for {robot.name}."
        )
    if max(found) != n or len(found) != n:
        have = ", ".join(found[k] for k in sorted(found))
        raise DataError(
            f"{t.path}: the data has joint columns {have}, but robot {robot.name} has {n} "
            f"joints (expected j1_deg .. j{n}_deg)."
        )
    cols = [found[k] for k in range(1, n + 1)]
    q = np.empty((len(t.rows), n))
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
        v = t.numbers(c)
        q[:, k] = {
            "deg": deg_to_rad,
            "rad": lambda x: x,
            "mm": mm_to_m,
            "m": lambda x: x,
        }[unit](v)
    deg_cols = [k for k, c in enumerate(cols) if c.endswith("_deg")]
    if deg_cols and len(t.rows) >= 5:
        vals = np.degrees(q[:, deg_cols])
        spread = vals.max(axis=0) - vals.min(axis=0)
        if np.abs(vals).max() <= 2 * np.pi + 1e-9 and spread.max() > 0.05:
            raise DataError(
                f"{t.path}: columns {cols[deg_cols[0]]}..{cols[deg_cols[-1]]}: every value is "
                f"within ±{2 * np.pi:.2f}, which looks like radians; convert to degrees or "
                "name the columns jK_rad."
            )
    return cols, q


def read_measurements(
    path: str | Path,
    robot: RobotDescription,
    targets: str | Path | Targets | None = None,
) -> Measurements:
    """Read and validate a measurement CSV for ``robot`` (see the module docstring).

    Raises
    ------
    DataError
        Missing column, unparsable or non-finite value, units that look wrong, joint count
        that does not match the robot, unknown target, empty file.
    """
    t = read_table(path)
    joint_cols, q = _joint_columns(t, robot)
    known = (
        set(joint_cols)
        | _OPTIONAL
        | set(_POINT)
        | set(_QUAT)
        | set(_WPR)
        | set(_SENSOR)
    )
    for c in t.header:
        if c not in known:
            base = c.lower().split("_")[0]
            if (
                base in _UNITLESS
                or c.lower() in _UNITLESS
                or _JOINT_RE.match(c.lower())
            ):
                raise DataError(
                    f"{t.path}: column {c!r} is not understood; column names carry their "
                    "unit (x_mm, sigma_mm, payload_kg, j1_deg, ...)."
                )
    if "target" in t.header or "xc_mm" in t.header:
        kind = "sensor"
        need: Sequence[str] = _SENSOR
    elif any(c in t.header for c in _QUAT):
        kind = "pose"
        need = (*_POINT, *_QUAT)
        if any(c in t.header for c in _WPR):
            raise DataError(
                f"{t.path}: give the orientation either as qw..qz or as w_deg, p_deg, "
                "r_deg, not both."
            )
    elif any(c in t.header for c in _WPR):
        kind = "pose"
        need = (*_POINT, *_WPR)
    else:
        kind = "point"
        need = _POINT
    for c in need:
        if c not in t.header:
            raise DataError(
                f"{t.path}: missing column '{c}' ({kind} data needs {', '.join(need)})."
            )
    set_index, set_labels = _labels(t, "set")
    marker_index, marker_labels = _labels(t, "marker")
    rows = np.array(t.lines, np.intp)
    common = {
        "set_index": set_index,
        "set_labels": set_labels,
        "marker_index": marker_index,
        "marker_labels": marker_labels,
        "rows": rows,
        "source": t.path,
        "sigma": mm_to_m(t.numbers("sigma_mm")) if "sigma_mm" in t.header else None,
        "sigma_rot": deg_to_rad(t.numbers("sigma_deg"))
        if "sigma_deg" in t.header
        else None,
        "payload_kg": t.numbers("payload_kg") if "payload_kg" in t.header else None,
    }
    for name in ("sigma", "sigma_rot", "payload_kg"):
        v = common[name]
        if v is not None and np.any(v <= 0):  # type: ignore[operator]
            i = int(np.flatnonzero(v <= 0)[0])  # type: ignore[operator]
            col = {
                "sigma": "sigma_mm",
                "sigma_rot": "sigma_deg",
                "payload_kg": "payload_kg",
            }[name]
            raise DataError(
                f"{t.path}: line {t.lines[i]}, column '{col}': must be positive."
            )
    if kind == "sensor":
        if targets is None:
            raise DataError(
                f"{t.path}: sensor data (target, xc_mm, ...) needs a --targets file."
            )
        tg = targets if isinstance(targets, Targets) else read_targets(targets)
        tnames = [s.strip() for s in t.column("target")]
        index = {lab: i for i, lab in enumerate(tg.labels)}
        for lab, line in zip(tnames, t.lines):
            if lab not in index:
                raise DataError(
                    f"{t.path}: line {line}, column 'target': {lab!r} is not in the targets file "
                    f"({', '.join(tg.labels)})."
                )
        pc = mm_to_m(
            np.column_stack([t.numbers(c) for c in ("xc_mm", "yc_mm", "zc_mm")])
        )
        return Measurements(
            "sensor",
            q,
            pc,
            target_index=np.array([index[s] for s in tnames], np.intp),
            targets=tg.p,
            target_labels=tg.labels,
            **common,  # type: ignore[arg-type]
        )
    xyz = np.column_stack([t.numbers(c) for c in _POINT])
    if (
        len(t.rows) >= 5
        and np.abs(xyz).max() < 5.0
        and np.ptp(xyz, axis=0).max() > 1e-3
    ):
        raise DataError(
            f"{t.path}: columns x_mm, y_mm, z_mm: every value is below 5, which looks like "
            "metres; convert to millimetres."
        )
    R = None
    if kind == "pose" and "w_deg" in t.header:
        R = wpr_to_matrix(deg_to_rad(np.column_stack([t.numbers(c) for c in _WPR])))
    elif kind == "pose":
        quat = np.column_stack([t.numbers(c) for c in _QUAT])
        nrm = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(nrm - 1.0) > 0.01)
        if bad.size:
            i = int(bad[0])
            raise DataError(
                f"{t.path}: line {t.lines[i]}, columns qw..qz: quaternion norm {nrm[i]:.4f}; "
                "expected a unit quaternion (w first)."
            )
        R = quat_wxyz_to_matrix(quat)
    return Measurements(kind, q, mm_to_m(xyz), R_user_cam=R, **common)  # type: ignore[arg-type]


@dataclass(frozen=True)
class CompensationTargets:
    """Targets to compensate: wanted tool points (and orientations) plus seed joints."""

    table: Table
    joint_columns: list[str]
    p: np.ndarray  # (N, 3) [m], user frame
    q_seed: np.ndarray  # (N, n) [rad]
    R: np.ndarray | None  # (N, 3, 3)
    set_index: np.ndarray
    set_labels: tuple[str, ...]
    marker_index: np.ndarray
    marker_labels: tuple[str, ...]


def read_compensation_targets(
    path: str | Path, robot: RobotDescription
) -> CompensationTargets:
    """Read a TARGETS.csv for ``kinecal compensate``: ``x_mm, y_mm, z_mm`` (user frame),
    optional ``qw, qx, qy, qz``, the seed joints ``j1_deg .. jN_deg``, optional ``set`` and
    ``marker``."""
    t = read_table(path)
    cols, q = _joint_columns(t, robot)
    for c in _POINT:
        if c not in t.header:
            raise DataError(
                f"{t.path}: missing column '{c}' (targets need x_mm, y_mm, z_mm)."
            )
    p = mm_to_m(np.column_stack([t.numbers(c) for c in _POINT]))
    R = None
    if any(c in t.header for c in _QUAT):
        for c in _QUAT:
            if c not in t.header:
                raise DataError(
                    f"{t.path}: missing column '{c}' (orientation needs qw, qx, qy, qz)."
                )
        quat = np.column_stack([t.numbers(c) for c in _QUAT])
        nrm = np.linalg.norm(quat, axis=1)
        bad = np.flatnonzero(np.abs(nrm - 1.0) > 0.01)
        if bad.size:
            raise DataError(
                f"{t.path}: line {t.lines[int(bad[0])]}, columns qw..qz: quaternion norm "
                f"{nrm[bad[0]]:.4f}; expected a unit quaternion (w first)."
            )
        R = quat_wxyz_to_matrix(quat)
    si, sl = _labels(t, "set")
    mi, ml = _labels(t, "marker")
    return CompensationTargets(t, cols, p, q, R, si, sl, mi, ml)
