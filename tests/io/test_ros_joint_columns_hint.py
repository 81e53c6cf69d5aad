"""A ROS user's joint_states export names its columns after the robot's joints, in
radians. kinecal said only "no joint columns; expected j1_deg .. j6_deg"; it now names
each such column and the ``jK_rad`` it should be."""

from __future__ import annotations

from pathlib import Path

import pytest

from kinecal.errors import DataError
from kinecal.io import read_measurements
from kinecal.robot import load_robot

UR = Path(__file__).resolve().parents[1] / "data" / "ur_e_series"


@pytest.mark.parametrize(
    "robot, names",
    [
        (
            "ur10e",
            ["shoulder_pan", "shoulder_lift", "elbow", "wrist_1", "wrist_2", "wrist_3"],
        ),
        (str(UR / "ur10e_like_ur_description.urdf"), None),
    ],
)
def test_columns_named_after_the_joints_are_named_in_the_error(tmp_path, robot, names):
    desc = load_robot(robot)
    cols = [f"{j}_joint" if names else j for j in (names or desc.joint_names)]
    f = tmp_path / "js.csv"
    f.write_text(
        ",".join([*cols, "x_mm", "y_mm", "z_mm"]) + "\n" + "0.1," * 6 + "1,2,3\n"
    )
    with pytest.raises(DataError) as info:
        read_measurements(f, desc)
    msg = str(info.value)
    assert msg.startswith(f"{f}: no joint columns")
    assert f"{cols[0]} -> j1_rad" in msg and f"{cols[5]} -> j6_rad" in msg


def test_other_columns_get_no_hint(tmp_path):
    f = tmp_path / "x.csv"
    f.write_text("a,b,x_mm,y_mm,z_mm\n1,2,3,4,5\n")
    with pytest.raises(DataError) as info:
        read_measurements(f, load_robot("ur10e"))
    assert "ROS" not in str(info.value)
