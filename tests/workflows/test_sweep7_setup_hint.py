"""``kinecal evaluate`` of a session whose set-up differs from the calibration's (the
tracker moved, the reflector nest re-mounted) without the matching ``--refit``: its
errors are the set-up's, not the robot's, and a warning now says which frames explain
them (before, 7.8 mm RMS with a std of 0.01 mm was printed as the robot's accuracy).
Data of the calibration's own set-up get no such warning."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.identification import calibrate
from kinecal.robot import load_robot
from kinecal.simulation import TrueRobot, robot_experiment, robot_truth
from kinecal.workflows import evaluate_measurements


@pytest.fixture(scope="module")
def session():
    robot = load_robot("fanuc-lrmate200id")
    truth = robot_truth(robot, seed=1)
    exp = robot_experiment(truth, 2, n_train=60, n_test=40)
    cal = calibrate(robot, exp.train, "full").calibrated
    return truth, exp, cal


def _hint(cal, meas, refit=()):
    got = evaluate_measurements(cal, meas, refit=refit)
    return [m for m in got.messages if "set-up differs" in m], got


def test_same_set_up_no_warning(session):
    _, exp, cal = session
    hints, got = _hint(cal, exp.test)
    assert not hints and got.evaluation.metrics.rms_mm < 0.05


def test_moved_tracker_is_named(session):
    _, exp, cal = session
    moved = replace(exp.test, p=exp.test.p + np.array([0.003, -0.002, 0.001]))
    hints, got = _hint(cal, moved)
    assert got.evaluation.metrics.rms_mm > 3.0
    assert len(hints) == 1 and "refitting the user frame" in hints[0]
    assert hints[0].endswith("--refit user.")
    assert not _hint(cal, moved, ("user",))[0]


def test_remounted_tool_is_named(session):
    truth, _, cal = session
    x = truth.params.copy()
    x[truth.model.cam_index[0, :3]] += [0.004, -0.003, 0.006]
    other = replace(truth, params=x)
    assert isinstance(other, TrueRobot)
    test = robot_experiment(other, 2, n_train=60, n_test=40).test
    hints, got = _hint(cal, test)
    assert got.evaluation.metrics.rms_mm > 5.0
    assert len(hints) == 1 and "refitting the tool frame" in hints[0], hints
    assert "re-mounted" in hints[0] and hints[0].endswith("--refit tool.")
    # with the user frame refitted (a new station too): the tool still named
    hints, _ = _hint(cal, test, ("user",))
    assert len(hints) == 1 and hints[0].endswith("--refit user,tool.")
    assert not _hint(cal, test, ("tool",))[0]
