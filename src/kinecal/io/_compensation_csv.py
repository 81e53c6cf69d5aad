"""``kinecal compensate``'s TARGETS.csv (file format: docs/files.md).

Beside :mod:`kinecal.io._csv`, whose measurement files every calibration reads: a
calibration does not create the class below (issue 36).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinecal.errors import DataError, expect_type
from kinecal.geometry import quat_wxyz_to_matrix, wpr_to_matrix
from kinecal.io._csv import (
    _POINT,
    _QUAT,
    _WPR,
    _joint_columns,
    _labels,
    _looks_like_metres,
    _payload,
    _unit_quaternions,
)
from kinecal.io._table import Table, read_table
from kinecal.measurement import Diagnostic
from kinecal.robot import RobotDescription
from kinecal.units import deg_to_rad, mm_to_m

__all__ = ["CompensationTargets", "read_compensation_targets"]


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
    diagnostics: list[Diagnostic] = field(default_factory=list)
    payload_kg: np.ndarray | None = None  # (N,) [kg], the payload_kg column


def read_compensation_targets(
    path: str | Path, robot: RobotDescription, *, allow_out_of_limits: bool = False
) -> CompensationTargets:
    """Read a TARGETS.csv for ``kinecal compensate``: ``x_mm, y_mm, z_mm`` (user frame),
    optional ``qw, qx, qy, qz``, the seed joints ``j1_deg``-``jN_deg``, optional ``set`` and
    ``marker``. Seeds beyond the joint limits are refused unless ``allow_out_of_limits``
    (then ``diagnostics`` says so)."""
    expect_type(robot, RobotDescription, "robot", "kinecal.robot.load_robot")
    t = read_table(path)
    cols, q, limits = _joint_columns(t, robot, allow_out_of_limits)
    for c in _POINT:
        if c not in t.header:
            raise DataError(
                f"{t.path}: missing column '{c}' (targets need x_mm, y_mm, z_mm)."
            )
    xyz = np.column_stack([t.numbers(c) for c in _POINT])
    _looks_like_metres(t, xyz, _POINT)  # (they were 'unreachable', exit 4)
    p = mm_to_m(xyz)
    R = None
    if any(c in t.header for c in (*_QUAT, *_WPR)):
        if any(c in t.header for c in _QUAT) and any(c in t.header for c in _WPR):
            raise DataError(
                f"{t.path}: give the orientation either as qw..qz or as w_deg, p_deg, "
                "r_deg, not both."
            )
        need = _WPR if any(c in t.header for c in _WPR) else _QUAT
        for c in need:
            if c not in t.header:
                raise DataError(
                    f"{t.path}: missing column '{c}' (orientation needs "
                    f"{', '.join(need)})."
                )
        if "w_deg" in t.header:
            R = wpr_to_matrix(deg_to_rad(np.column_stack([t.numbers(c) for c in _WPR])))
        else:
            R = quat_wxyz_to_matrix(_unit_quaternions(t))
    si, sl = _labels(t, "set")
    mi, ml = _labels(t, "marker")
    found = [] if limits is None else [limits]
    load = _payload(t, robot) if "payload_kg" in t.header else None
    return CompensationTargets(t, cols, p, q, R, si, sl, mi, ml, found, load)
