"""Issue 31: the default (``--model auto``) against the best fixed model on a matrix of
twins: four robots (a UR-type arm, a generic 6R arm, the 7-axis FR3, the long-arm LR
Mate) x four truths (geometry only; with gravity deflection; with transmission errors;
both), calibrated on 150 poses from one end of the workspace and scored on 800 from the
other with the tracker moved and user and tool frames refitted (a new session in
another region). Over this matrix and a second one at 40 poses, random splits and two
seeds (128 cases, docs/theory.md), the default was within 1.05x of the best fixed model
in all but two: 40 poses of a 6R arm whose truth has transmission errors and no gravity
deflection, where `ntm` was chosen and `full` extrapolated better (1.14x, 1.26x)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.geometry import euler_zyx_to_matrix
from kinecal.identification import (
    CalibrationOptions,
    calibrate,
    evaluate,
    pose_features,
    select_model,
)
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, robot_experiment, robot_truth

TRUTHS = {
    "geometry": {"ntm_amplitude": 0.0, "deflection": 1e-9},
    "gravity": {"ntm_amplitude": 0.0},
    "transmission": {"deflection": 1e-9},
    "both": {},
}


def _new_region(name: str, truth_kind: str, seed: int = 0):
    robot = load_robot(name)
    truth = robot_truth(robot, seed=seed, **TRUTHS[truth_kind])
    e = robot_experiment(
        truth, seed, n_train=10, n_test=3000, tracker=LaserTracker(10e-6, 0.0)
    )
    pool = e.test
    f = pose_features(pool.q_ctrl, robot)
    c = f - f.mean(axis=0)
    along = c @ np.linalg.svd(c, full_matrices=False)[2][0]
    lo, hi = np.quantile(along, [0.4, 0.6])
    rng = np.random.default_rng(seed)
    train = pool.subset(np.sort(rng.choice(np.flatnonzero(along < lo), 150, False)))
    test = pool.subset(np.sort(rng.choice(np.flatnonzero(along > hi), 800, False)))
    R = euler_zyx_to_matrix(np.radians([25.0, 1.0, -2.0]))
    return robot, train, replace(test, p=test.p @ R.T + [0.2, -0.3, 0.05])


@pytest.mark.slow
@pytest.mark.parametrize("truth_kind", sorted(TRUTHS))
@pytest.mark.parametrize(
    "name", ["ur5e", "generic-6r", "franka-fr3", "fanuc-lrmate200id-7l"]
)
def test_default_within_5_percent_of_the_best_fixed_model_in_a_new_region(
    name, truth_kind
):
    robot, train, test = _new_region(name, truth_kind)
    refit = ("user", "tool")
    fixed = {
        m: evaluate(
            calibrate(robot, train, m).calibrated, test, refit=refit
        ).metrics.rms_mm
        for m in ("kinematic", "ntm", "rfcm", "full")
    }
    sel = select_model(robot, train)
    opts = CalibrationOptions().tuned(prior_scale=sel.prior_scale)
    res = sel.calibration(opts) or calibrate(robot, train, sel.spec, opts)
    got = evaluate(res.calibrated, test, refit=refit).metrics.rms_mm
    assert got <= 1.05 * min(fixed.values()), (sel.spec.name, got, fixed)
