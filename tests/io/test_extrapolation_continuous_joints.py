"""Extrapolation warnings on a robot with continuous joints (a URDF's joints without
limits: Kinova Gen3's J1, J3, J5, J7): every term of the model repeats each turn, so an
angle a whole number of turns from the calibrated range is inside it. Before, a pose at
J5 176 deg against a calibrated -413 .. 152 deg was warned about as an extrapolation."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from kinecal.identification import calibrate
from kinecal.io._checks import extrapolation
from kinecal.robot import load_robot
from kinecal.simulation import robot_experiment, robot_truth

GEN3 = (
    Path(__file__).resolve().parents[1]
    / "data"
    / "vendor_urdf"
    / "kinova_gen3_7dof.urdf"
)


def test_whole_turns_are_inside_and_a_limited_joint_is_still_checked():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        robot = load_robot(str(GEN3))
    exp = robot_experiment(robot_truth(robot, seed=1), 1, n_train=60, n_test=10)
    cal = calibrate(robot, exp.train, "kinematic").calibrated
    rng = np.radians(np.asarray(cal.info["calibrated_joint_range"]))
    q = exp.train.q_ctrl[:10].copy()
    assert extrapolation(cal, q, range(10), "t") is None
    turned = q.copy()
    turned[:, 0] += 2 * np.pi  # J1 continuous: a whole turn on
    turned[:, 4] -= 4 * np.pi  # J5 continuous: two turns back
    assert extrapolation(cal, turned, range(10), "t") is None
    beyond = q.copy()
    beyond[0, 0] = rng[0, 1] + np.radians(40.0)  # J1 past its range, not a whole turn
    span = rng[0, 1] - rng[0, 0]
    d = extrapolation(cal, beyond, range(10), "t")
    assert (d is not None) == (span < np.radians(315.0))
    limited = q.copy()
    limited[0, 1] = rng[1, 1] + np.radians(20.0) + 2 * np.pi  # J2 has limits
    d = extrapolation(cal, limited, range(10), "t")
    assert d is not None and d.rows == (0,)
