"""Issue 31: folds that imitate a new session (regions of the workspace, whole sets), one
cross-validation path for ``--cv`` and ``--model auto``, and warnings for poses outside
the calibrated joint ranges."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.geometry import euler_zyx_to_matrix
from kinecal.identification import (
    Measurements,
    calibrate,
    cross_validate,
    held_out_accuracy,
    make_folds,
    pose_features,
    region_labels,
    select_model,
)
from kinecal.io import extrapolation
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, experiment2

ROBOT = load_robot("fanuc-lrmate200id")


@pytest.fixture(scope="module")
def poses_200():
    e = experiment2(21, tracker=LaserTracker(5e-6, 0.0))
    return e.test.subset(np.random.default_rng(5).permutation(e.test.n)[:200])


def _nearest_training_distance(meas, folds) -> float:
    """Mean distance (nominal joint-frame positions) of a held-out pose to the nearest
    training pose, over all folds [m]."""
    f = pose_features(meas.q_ctrl, ROBOT)
    out = []
    for t in folds.test:
        train = np.setdiff1d(np.arange(meas.n), t)
        d = np.linalg.norm(f[t][:, None, :] - f[train][None, :, :], axis=2)
        out.append(d.min(axis=1))
    return float(np.concatenate(out).mean())


def test_region_folds_hold_out_whole_parts_of_the_workspace(poses_200):
    """Region folds: balanced, deterministic, every row in one fold, and their held-out
    poses lie clearly farther from the training poses than random folds' do."""
    region = make_folds(poses_200, 5, scheme="region", robot=ROBOT)
    again = make_folds(poses_200, 5, seed=7, scheme="region", robot=ROBOT)
    rand = make_folds(poses_200, 5, scheme="random")
    assert region.unit == "region" and rand.unit == "pose"
    sizes = [t.size for t in region.test]
    assert max(sizes) - min(sizes) <= 1
    assert np.array_equal(np.sort(np.concatenate(region.test)), np.arange(200))
    assert all(np.array_equal(a, b) for a, b in zip(region.test, again.test))
    far, near = (_nearest_training_distance(poses_200, f) for f in (region, rand))
    assert far > 1.3 * near, (far, near)


def test_region_labels_cut_across_the_widest_spread():
    """Two clusters far apart along one axis are never mixed by a 2-region split; k
    regions of N rows have sizes N/k within one."""
    rng = np.random.default_rng(0)
    x = np.concatenate(
        [rng.normal(0, 1, (30, 3)), rng.normal(0, 1, (30, 3)) + np.array([50.0, 0, 0])]
    )
    lab = region_labels(x, 2)
    assert len(set(lab[:30])) == 1 and len(set(lab[30:])) == 1 and lab[0] != lab[-1]
    for k in (3, 5, 7):
        sizes = np.bincount(region_labels(rng.normal(size=(101, 4)), k), minlength=k)
        assert sizes.max() - sizes.min() <= 1


def test_poses_measured_together_stay_in_one_region():
    """Rows at the same joints (several markers) share a fold."""
    e = experiment2(2, tracker=LaserTracker(5e-6, 0.0))
    m = e.test.subset(np.arange(60))
    both = m.subset(np.concatenate([np.arange(60), np.arange(60)]))
    folds = make_folds(both, 4, scheme="region", robot=ROBOT)
    for t in folds.test:
        q = {tuple(np.round(r, 9)) for r in both.q_ctrl[t]}
        others = np.setdiff1d(np.arange(both.n), t)
        assert not q & {tuple(np.round(r, 9)) for r in both.q_ctrl[others]}


def test_cv_and_auto_give_the_same_figures_on_the_same_folds(poses_200):
    """One path: the chosen candidate's region figure in the selection's table is what
    --cv reports for it; its in-session figure comes from the same fit on random
    folds and equals a fresh scoring of those folds."""
    sel = select_model(ROBOT, poses_200, k=5)
    chosen = next(c for c in sel.candidates if c.chosen)
    held = held_out_accuracy(ROBOT, poses_200, sel.spec, 5, selection=sel)
    assert [f.name for f in held.figures] == ["in-session", "new region"]
    assert held.transfer.model.rms_mm == chosen.cv_rms_mm
    random_folds = make_folds(poses_200, 5, scheme="pose", robot=ROBOT)
    again = sel.chosen_cv(random_folds)
    assert not isinstance(again, ValueError)
    assert again.rms_mm == pytest.approx(held.figure("in-session").model.rms_mm)
    d = held.as_dict()
    assert set(d["figures"]) == {"in-session", "new region"}
    assert d["advice"] and "second session" in d["advice"][0]


def test_cv_figures_of_a_fixed_model_match_fold_by_fold_calibrations(poses_200):
    """--cv of a fixed model (the shared path) against calibrating every fold from
    nominal (cross_validate): within 3 %, on both kinds of folds."""
    spec = next(
        c.spec for c in select_model(ROBOT, poses_200).candidates if c.label == "full"
    )
    held = held_out_accuracy(ROBOT, poses_200, spec, 5)
    for fig, scheme in zip(held.figures, ("pose", "region")):
        exact = cross_validate(ROBOT, poses_200, spec, k=5, scheme=scheme)
        assert fig.model.rms_mm == pytest.approx(exact.rms_mm, rel=0.03)
        assert fig.nominal.rms_mm > 10 * fig.model.rms_mm


def test_several_sessions_give_a_new_session_figure():
    e = experiment2(4, tracker=LaserTracker(5e-6, 0.0))
    parts = []
    for k in range(3):
        m = e.test.subset(np.arange(80 * k, 80 * k + 80))
        R = euler_zyx_to_matrix(np.radians([15.0 * k, 1.0, 0.0]))
        parts.append(replace(m, p=m.p @ R.T + [0.1 * k, 0.0, 0.0]))
    meas = Measurements(
        "point",
        np.concatenate([p.q_ctrl for p in parts]),
        np.concatenate([p.p for p in parts]),
        set_index=np.repeat(np.arange(3), 80),
        set_labels=("a", "b", "c"),
    )
    held = held_out_accuracy(
        ROBOT, meas, calibrate(ROBOT, meas, "kinematic").calibrated.model.spec, 3
    )
    assert [f.name for f in held.figures] == ["in-session", "new session"]
    assert held.transfer.folds.unit == "set" and not held.notes
    assert held.as_dict()["unit"] == "set"


def test_extrapolation_names_rows_and_joints(poses_200):
    """A model calibrated on part of the J1 range warns for poses beyond it, naming the
    rows and the joint; poses inside give no warning."""
    q = poses_200.q_ctrl
    inside = q[:, 0] < np.quantile(q[:, 0], 0.6)
    train, test = poses_200.subset(inside), poses_200.subset(~inside)
    cal = calibrate(ROBOT, train, "kinematic").calibrated
    rng = np.asarray(cal.info["calibrated_joint_range"])
    assert rng.shape == (6, 2)
    assert rng[0, 1] == pytest.approx(np.degrees(train.q_ctrl[:, 0].max()), abs=1e-5)
    assert extrapolation(cal, train.q_ctrl, train.rows, "train") is None
    d = extrapolation(cal, test.q_ctrl, test.rows, "test")
    assert d is not None and d.code == "extrapolation"
    far = test.q_ctrl[:, 0] > np.radians(rng[0, 1]) + np.radians(
        max(0.02 * np.ptp(rng[0]), 1.0)
    )
    assert {int(r) for r in test.rows[far]} <= set(d.rows) and far.sum() > 5
    assert (
        "J1" in d.message or "joint1" in d.message or ROBOT.joint_names[0] in d.message
    )
    # A model file without the ranges (an older file) is not checked.
    old = replace(
        cal, info={k: v for k, v in cal.info.items() if k != "calibrated_joint_range"}
    )
    assert extrapolation(old, test.q_ctrl, test.rows, "test") is None


def test_cv_of_a_fixed_model_equals_autos_table_row(poses_200):
    """Issue 31's two disagreeing figures: `--model full --cv K` and `--model auto`'s
    table row for full are one computation on the same folds."""
    sel = select_model(ROBOT, poses_200, k=4)
    row = next(c for c in sel.candidates if c.label == "full" and c.prior_scale == 1.0)
    spec = calibrate(
        ROBOT, poses_200.subset(np.arange(60)), "full"
    ).calibrated.model.spec
    assert spec == row.spec
    held = held_out_accuracy(ROBOT, poses_200, spec, 4)
    assert held.transfer.model.rms_mm == pytest.approx(row.cv_rms_mm, rel=1e-9)
