"""Pose data whose measured orientations turn about one axis only (or not at all) cannot
fix the tool's and the user frame's rotation: ``calibrate`` refuses it naming the data
(it ended in an internal error inside the hand-eye solve)."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.geometry import matrix_to_quat_wxyz
from kinecal.robot import load_robot
from tests.cli_contract import run_kinecal


def _pose_csv(path, q_deg, robot):
    T = robot.fk_flange(np.radians(q_deg))
    quat = matrix_to_quat_wxyz(T[:, :3, :3])
    p = T[:, :3, 3] * 1e3
    head = [f"j{k + 1}_deg" for k in range(q_deg.shape[1])]
    head += ["x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"]
    rows = [",".join(head)]
    rows += [
        ",".join(f"{v:.9f}" for v in (*qk, *pk, *wk))
        for qk, pk, wk in zip(q_deg, p, quat)
    ]
    path.write_text("\n".join(rows) + "\n")


@pytest.mark.parametrize("moving", [[0], [0, 6]])  # J1 alone; J1 and J7 (both vertical)
def test_orientations_about_one_axis_are_refused_naming_the_data(
    moving, tmp_path, capsys
):
    robot = load_robot("franka-fr3")
    rng = np.random.default_rng(3)
    q = np.tile([0.0, -30.0, 0.0, -120.0, 0.0, 90.0, 45.0], (40, 1))
    # At these J2..J6 the flange axis (J7's) points straight down, parallel to J1's:
    # J1 and J7 turn the tool about one direction only.
    for j in moving:
        q[:, j] += rng.uniform(-60, 60, 40)
    data = tmp_path / "one_axis.csv"
    _pose_csv(data, q, robot)
    out = tmp_path / "out"
    res = run_kinecal(
        capsys,
        "calibrate",
        data,
        "--robot",
        "franka-fr3",
        "--out",
        out,
        "--model",
        "kinematic",
        "--cv",
        "off",
    )
    assert res.code == 2, str(res)
    assert str(data) in res.err and "two different axes" in res.err, res.err
    assert "internal error" not in res.err
    assert not out.exists()
