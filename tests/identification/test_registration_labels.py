"""Pose data are registered twice: with the default weights, then with the position and
orientation noise estimated from the first fit's residuals. The progress display and
report.json's stages named both "registration", so a user saw one step printed twice."""

from __future__ import annotations

import warnings
from pathlib import Path

from kinecal.identification import calibrate
from kinecal.io import read_measurements
from kinecal.robot import load_robot

REAL = Path(__file__).resolve().parents[1] / "data" / "real"


def test_the_two_registrations_of_pose_data_have_their_own_names():
    robot = load_robot("franka-fr3")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(REAL / "fr3_session_a.csv", robot)
    lines: list[str] = []
    res = calibrate(robot, meas, "kinematic", progress=lambda s, d: lines.append(s))
    names = [s.name for s in res.stages]
    assert names[:2] == ["registration", "registration (noise weights)"]
    assert lines.count("registration") == 1
    assert "registration (noise weights)" in lines
