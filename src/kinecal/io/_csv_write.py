"""Write measurement and target CSVs in the format :mod:`kinecal.io._csv` reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kinecal.geometry import matrix_to_quat_wxyz
from kinecal.io._csv_format import Column, csv_text
from kinecal.io._files import atomic_write_text
from kinecal.measurement import Measurements
from kinecal.robot import RobotDescription

_POINT = ("x_mm", "y_mm", "z_mm")
_QUAT = ("qw", "qx", "qy", "qz")

__all__ = [
    "joint_column_names",
    "measurements_to_csv",
    "write_measurements",
    "write_targets",
]


def joint_column_names(robot: RobotDescription) -> list[str]:
    """The joint columns ``j1_deg``-``jN_deg`` (``jK_mm`` for prismatic joints)."""
    return [
        f"j{k + 1}_{'mm' if j.kind == 'prismatic' else 'deg'}"
        for k, j in enumerate(robot.joints)
    ]


def _joint_values(robot: RobotDescription, q: np.ndarray) -> np.ndarray:
    scale = np.array(
        [1e3 if j.kind == "prismatic" else 180.0 / np.pi for j in robot.joints]
    )
    return q * scale


def measurements_to_csv(meas: Measurements, robot: RobotDescription) -> str:
    """The CSV text of ``meas`` (mm, deg; 6 decimals in mm, 8 in deg), written column by
    column (:func:`kinecal.io.csv_text`)."""
    q = _joint_values(robot, meas.q_ctrl)
    cols: list[tuple[str, Column]] = []
    if meas.kind == "sensor":
        assert meas.target_index is not None
        cols.append(("target", Column.labels(meas.target_labels, meas.target_index)))
    if len(meas.set_labels) > 1 or meas.set_labels[0]:
        cols.append(("set", Column.labels(meas.set_labels, meas.set_index)))
    if len(meas.marker_labels) > 1 or meas.marker_labels[0]:
        cols.append(("marker", Column.labels(meas.marker_labels, meas.marker_index)))
    for k, name in enumerate(joint_column_names(robot)):
        cols.append((name, Column.numbers(q[:, k], "%.8f")))
    p_mm = meas.p * 1e3
    names = ("xc_mm", "yc_mm", "zc_mm") if meas.kind == "sensor" else _POINT
    cols += [(c, Column.numbers(p_mm[:, a], "%.6f")) for a, c in enumerate(names)]
    if meas.kind == "pose":
        assert meas.R_user_cam is not None
        quat = matrix_to_quat_wxyz(meas.R_user_cam)
        cols += [(c, Column.numbers(quat[:, a], "%.12f")) for a, c in enumerate(_QUAT)]
    for name, arr, scale in (
        ("payload_kg", meas.payload_kg, 1.0),
        ("sigma_mm", meas.sigma, 1e3),
        ("sigma_deg", meas.sigma_rot, 180.0 / np.pi),
    ):
        if arr is not None:
            cols.append((name, Column.numbers(np.asarray(arr) * scale, "%.10g")))
    return csv_text(cols)


def write_measurements(
    path: str | Path,
    meas: Measurements,
    robot: RobotDescription,
    *,
    force: bool = False,
) -> Path:
    """Write a measurement CSV atomically."""
    return atomic_write_text(path, measurements_to_csv(meas, robot), force=force)


def write_targets(
    path: str | Path,
    labels: tuple[str, ...],
    p: np.ndarray,
    radius: np.ndarray | None = None,
    *,
    force: bool = False,
) -> Path:
    """Write a targets CSV ``target, x_mm, y_mm, z_mm[, r_mm]``."""
    p_mm = np.asarray(p, dtype=np.float64).reshape(-1, 3) * 1e3
    cols = [("target", Column.text(labels))]
    cols += [(c, Column.numbers(p_mm[:, a], "%.6f")) for a, c in enumerate(_POINT)]
    if radius is not None:
        cols.append(("r_mm", Column.numbers(np.asarray(radius) * 1e3, "%.6f")))
    return atomic_write_text(path, csv_text(cols), force=force)
