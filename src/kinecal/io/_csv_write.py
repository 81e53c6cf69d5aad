"""Write measurement and target CSVs in the format :mod:`kinecal.io._csv` reads."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from kinecal.geometry import matrix_to_quat_wxyz
from kinecal.identification import Measurements
from kinecal.io._files import atomic_write_text
from kinecal.robot import RobotDescription

__all__ = [
    "joint_column_names",
    "measurements_to_csv",
    "write_measurements",
    "write_targets",
]


def joint_column_names(robot: RobotDescription) -> list[str]:
    """``j1_deg .. jN_deg`` (``jK_mm`` for prismatic joints)."""
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
    """The CSV text of ``meas`` (mm, deg; 6 decimals in mm, 8 in deg)."""
    cols = joint_column_names(robot)
    data: list[np.ndarray] = [_joint_values(robot, meas.q_ctrl)]
    fmt = ["%.8f"] * len(cols)
    labels: list[tuple[str, list[str]]] = []
    if meas.kind == "sensor":
        assert meas.target_index is not None
        labels.append(("target", [meas.target_labels[i] for i in meas.target_index]))
        cols += ["xc_mm", "yc_mm", "zc_mm"]
    else:
        cols += ["x_mm", "y_mm", "z_mm"]
    data.append(meas.p * 1e3)
    fmt += ["%.6f"] * 3
    if meas.kind == "pose":
        assert meas.R_user_cam is not None
        cols += ["qw", "qx", "qy", "qz"]
        data.append(matrix_to_quat_wxyz(meas.R_user_cam))
        fmt += ["%.12f"] * 4
    if len(meas.set_labels) > 1 or meas.set_labels[0]:
        labels.append(("set", [meas.set_labels[i] for i in meas.set_index]))
    if len(meas.marker_labels) > 1 or meas.marker_labels[0]:
        labels.append(("marker", [meas.marker_labels[i] for i in meas.marker_index]))
    for name, arr, scale, f in (
        ("payload_kg", meas.payload_kg, 1.0, "%.10g"),
        ("sigma_mm", meas.sigma, 1e3, "%.10g"),
        ("sigma_deg", meas.sigma_rot, 180.0 / np.pi, "%.10g"),
    ):
        if arr is not None:
            cols.append(name)
            data.append(np.asarray(arr)[:, None] * scale)
            fmt.append(f)
    num = np.column_stack(data)
    buf = io.StringIO()
    buf.write(",".join([lab for lab, _ in labels] + cols) + "\n")
    for i in range(meas.n):
        lead = [vals[i] for _, vals in labels]
        buf.write(",".join(lead + [f % v for f, v in zip(fmt, num[i])]) + "\n")
    return buf.getvalue()


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
    head = "target,x_mm,y_mm,z_mm" + (",r_mm" if radius is not None else "")
    lines = [head]
    for k, lab in enumerate(labels):
        row = [lab, *(f"{v * 1e3:.6f}" for v in p[k])]
        if radius is not None:
            row.append(f"{radius[k] * 1e3:.6f}")
        lines.append(",".join(row))
    return atomic_write_text(path, "\n".join(lines) + "\n", force=force)
