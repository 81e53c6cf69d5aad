"""Issue 20, point 4: a wrong nominal robot is named, and so are the parameters the
priors hold near nominal values the data reject (a fit without the geometry priors on
the fly)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from kinecal.identification import CalibrationOptions, calibrate
from kinecal.identification._nominal_check import nominal_check
from kinecal.io import read_measurements
from kinecal.robot import load_robot
from kinecal.simulation import experiment2

REAL = Path(__file__).resolve().parents[1] / "data" / "real"


def _calibrate(robot, meas, model="kinematic", **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return calibrate(robot, meas, model, CalibrationOptions(**kw))


@pytest.fixture(scope="module")
def mocap():
    """The FIGAROH mocap poses of a UR10e."""
    return read_measurements(REAL / "ur10_mocap.csv", load_robot("ur10e"))


def test_issue_20_cb_table_on_ur10e_poses_is_flagged(mocap):
    cb = load_robot("ur10")
    res = _calibrate(cb, mocap)
    found = nominal_check(res, cb, mocap)
    assert [d.code for d in found] == ["priors_held", "nominal_mismatch"]
    held = found[0]
    # The UR10e's d4 (on the parallel axes 2-4: joint2.d) and d5 are 10.2 and 4.15 mm
    # longer than the CB table's; the priors hold them at a fraction of that (joint2.d
    # the most).
    assert held.parameters[0] == "joint2.d"
    assert "--priors compliance" in held.message
    assert "ur10 with fitted frames leaves 10.97 mm" in found[1].message


@pytest.mark.parametrize("model", ["kinematic", "full"])
def test_issue_20_the_right_nominal_passes(mocap, model):
    robot = load_robot("ur10e")
    res = _calibrate(robot, mocap, model)
    assert nominal_check(res, robot, mocap) == []


def test_issue_20_fr3_and_a_simulated_lr_mate_pass():
    fr3 = load_robot("franka-fr3")
    m = read_measurements(REAL / "fr3_session_a.csv", fr3)
    assert nominal_check(_calibrate(fr3, m), fr3, m) == []
    e = experiment2(3, n_train=100, n_side=6)
    lrmate = load_robot("fanuc-lrmate200id")
    res = _calibrate(lrmate, e.train, "full")
    assert nominal_check(res, lrmate, e.train) == []


def test_issue_20_another_robots_table_is_flagged():
    """LR Mate data on the LR Mate /7L table (links 100 mm longer): the priors widen to
    let the data through, and the check says why."""
    e = experiment2(3, n_train=100, n_side=6)
    wrong = load_robot("fanuc-lrmate200id-7l")
    res = _calibrate(wrong, e.train)
    found = nominal_check(res, wrong, e.train)
    assert [d.code for d in found] == ["nominal_mismatch"]
    assert "joint" in found[0].parameters[0]
    assert "far from nominal" in found[0].message


def test_issue_20_without_priors_there_is_nothing_to_hold(mocap):
    cb = load_robot("ur10")
    res = _calibrate(cb, mocap, priors="none")
    assert nominal_check(res, cb, mocap) == []


def test_issue_20_a_given_unconstrained_fit_is_used(mocap):
    cb = load_robot("ur10")
    res = _calibrate(cb, mocap)
    ls = _calibrate(cb, mocap, priors="none")
    assert [d.code for d in nominal_check(res, cb, mocap, unconstrained=ls)] == [
        "priors_held",
        "nominal_mismatch",
    ]
