"""``export-urdf --format yaml-dh`` wrote ``-0.0`` for a zero that came out of a rounding
or a sign flip (alpha, a limit, a frame angle): a robot file a user reads and edits should
not show negative zeros. The values are the same numbers; the text is cleaner."""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from kinecal.io._urdf_export import robot_yaml_text
from kinecal.robot import load_robot


def test_no_negative_zero_in_the_robot_yaml():
    robot = load_robot("ur10e")
    joints = list(robot.joints)
    joints[1] = replace(joints[1], alpha=-0.0, theta_offset=-0.0)
    limits = np.radians([-1e-12, 360.0])
    joints[2] = replace(joints[2], limits=(float(limits[0]), float(limits[1])))
    T = robot.T_n_flange.copy()
    T[:3, 3] = [-0.0, 0.0, -0.0]
    text = robot_yaml_text(
        replace(robot, joints=tuple(joints), T_n_flange=T), comments=[]
    )
    assert not re.search(r"-0\.0\b(?![0-9]*[1-9])", text), text
    assert "alpha: 0.0" in text
