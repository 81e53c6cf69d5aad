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
    res = calibrate(
        ROBOT, train, spec_or_name, CalibrationOptions().tuned(prior_scale=scale)
    )
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


def test_worker_processes_give_the_serial_selection(exp2_exact, one_blas_thread):
    """20 poses: the largest candidates cannot be fitted on 16 and are skipped; the
    table, the choice and the skipped runs are the same with two workers."""
    e = exp2_exact
    train = e.train.subset(
        np.sort(np.random.default_rng(0).choice(e.train.n, 20, replace=False))
    )
    said: dict[int, list[str]] = {1: [], 2: []}
    sels = {
        j: select_model(
            ROBOT, train, k=5, jobs=j, progress=lambda s, d, j=j: said[j].append(d)
        )
        for j in (1, 2)
    }
    assert sels[1].as_dict() == sels[2].as_dict()
    assert sels[1].spec == sels[2].spec
    assert said[1] == said[2]
    assert any("skipped" in d for d in said[1]), said[1]


def test_cross_validate_many_reports_a_failing_run_and_scores_the_others(
    exp2_exact, one_blas_thread
):
    from kinecal.identification import cross_validate, cross_validate_many

    train = exp2_exact.train.subset(np.arange(15))  # 12 training poses per fold
    kin, full = cross_validate_many(
        ROBOT, train, [("kinematic", None), ("full", None)], k=5, jobs=2
    )
    assert isinstance(full, ValueError) and "poses" in str(full)
    alone = cross_validate(ROBOT, train, "kinematic", k=5)
    assert [f.rms_mm for f in kin.folds] == [f.rms_mm for f in alone.folds]
    with pytest.raises(ValueError, match="poses"):
        cross_validate(ROBOT, train, "full", k=5, jobs=2)
