"""``--model auto`` (issue 11): cross-validated term selection never punishes the user."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import (
    CalibrationOptions,
    calibrate,
    evaluate,
    select_model,
)
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, experiment2, random_truth

ROBOT = load_robot("fanuc-lrmate200id")


def _held_out(train, test, spec_or_name, scale=1.0):
    res = calibrate(ROBOT, train, spec_or_name, CalibrationOptions(prior_scale=scale))
    return evaluate(res.calibrated, test).metrics.rms_mm


def _auto(train, test):
    sel = select_model(ROBOT, train, k=5)
    return sel, _held_out(train, test, sel.spec, sel.prior_scale)


def test_auto_with_100_poses_keeps_the_compliance_and_matches_full(exp2_exact):
    e = exp2_exact
    test = e.test.subset(np.arange(0, e.test.n, 5))
    sel, auto = _auto(e.train, test)
    full = _held_out(e.train, test, "full")
    kin = _held_out(e.train, test, "kinematic")
    assert sel.spec.load, sel.as_dict()
    assert auto <= 1.05 * full, (auto, full)
    assert auto < 0.9 * kin
    table = sel.as_dict()
    assert sum(c["chosen"] for c in table["candidates"]) == 1
    assert {"kinematic", "full"} <= {c["label"] for c in table["candidates"]}


@pytest.mark.parametrize("seed", [0, 1])
def test_auto_with_30_poses_is_never_worse_than_kinematic(exp2_exact, seed):
    e = exp2_exact
    rng = np.random.default_rng(seed)
    train = e.train.subset(np.sort(rng.choice(e.train.n, 30, replace=False)))
    test = e.test.subset(np.arange(0, e.test.n, 5))
    sel, auto = _auto(train, test)
    kin = _held_out(train, test, "kinematic")
    assert auto <= 1.02 * kin, (sel.spec.name, auto, kin)


def test_auto_drops_compliance_the_truth_does_not_have():
    truth = random_truth(ROBOT, seed=21, ntm_amplitude=0.0, compliance=0.0)
    e = experiment2(21, truth=truth, tracker=LaserTracker(5e-6, 0.0))
    test = e.test.subset(np.arange(0, e.test.n, 5))
    sel, auto = _auto(e.train, test)
    kin = _held_out(e.train, test, "kinematic")
    assert auto <= 1.02 * kin, (sel.spec.name, auto, kin)
    # Nothing beyond the geometry is in the truth: the kinematic model is chosen.
    assert not sel.spec.ntm_joints and not sel.spec.load, sel.as_dict()
