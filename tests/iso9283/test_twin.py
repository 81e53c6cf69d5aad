"""Issue 38 point 2 on the digital twin: a robot with every modelled error (geometry,
transmission, gravity compliance, payload) calibrated from 100 tracker poses, then the
ISO cube test measured on it before and after compensation."""

from __future__ import annotations

import math

import numpy as np

from kinecal.identification import Measurements, calibrate
from kinecal.iso9283 import compensated_plan, evaluate_iso9283, plan_iso9283
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, robot_experiment, robot_truth
from tests.iso9283.test_characteristics import MAXWELL_MEAN, MAXWELL_STD

SIGMA = math.hypot(5e-6, 15e-6)  # tracker 5 um and robot repeatability 15 um per axis


def test_issue_38_iso_figures_of_a_twin_calibration_before_and_after():
    robot = load_robot("fanuc-lrmate200id")
    truth = robot_truth(robot, seed=1)
    exp = robot_experiment(truth, seed=1, n_train=100, n_test=10)
    cal = calibrate(robot, exp.train, "full").calibrated
    rng = np.random.default_rng(5)
    tracker = LaserTracker(5e-6, 0.0)

    def measure(plan):
        p, _ = truth.evaluate(plan.q_ctrl)
        p = tracker.measure(p, rng)[0] + rng.normal(0.0, 15e-6, p.shape)
        load = np.full(len(p), robot.payload_kg) if robot.payload_kg else None
        return Measurements("point", plan.q_ctrl, p, payload_kg=load)

    before = plan_iso9283(robot, edge=0.25, centre=[0.35, 0.0, 0.2])
    iso = evaluate_iso9283(cal, measure(before), before.labels, before.cycle)
    nominal_ap = max(f.ap for f in iso.nominal.points)
    model_ap = max(f.ap for f in iso.model.points)
    assert nominal_ap > 0.2e-3  # the robot's errors, before compensation
    assert model_ap < 0.03e-3  # left after compensation (predicted)
    # measured at the compensated joints: the accuracy after compensation
    after = compensated_plan(before, cal)
    iso_after = evaluate_iso9283(cal, measure(after), after.labels, after.cycle)
    assert max(f.ap for f in iso_after.model.points) < 0.03e-3
    # repeatability: the scatter's 3-D bound, the same whichever model commands
    rp_true = (MAXWELL_MEAN + 3 * MAXWELL_STD) * SIGMA
    for run in (iso, iso_after):
        rp = np.mean([f.rp for f in run.model.points])
        assert abs(rp - rp_true) < 4 * 0.3 * SIGMA / math.sqrt(5)
