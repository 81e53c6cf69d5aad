"""Issue 31 point 5: reported standard deviations against the spread of the estimates over
left-out poses (calibrating again without each pose), on real data. The covariance of
independent rows misses residuals that move together (three markers per TIAGo pose, an
effect the model lacks): the reported covariance is widened to the jackknife over
left-out poses (Eq. (T-3b)) in the directions where that is clearly larger (Eq. (T-3d)).
Parameters whose variance is mostly their prior's part (``prior_dominated``, Eq. (T-3c))
keep it: every refit is held alike, so the spread over left-out poses cannot show what
the prior holds; they are compared apart."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kinecal._stats import median
from kinecal.identification import Measurements, calibrate, make_folds
from kinecal.io import read_measurements
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, experiment2

ROOT = Path(__file__).resolve().parents[2]
REAL = ROOT / "tests" / "data" / "real"
REAL_SETS = {
    "ur10e": ("ur10_mocap.csv", "ur10e"),
    "fr3": ("fr3_session_a.csv", "franka-fr3"),
    "tiago": (
        "tiago_mocap.csv",
        str(ROOT / "examples" / "data" / "tiago_figaroh_qualisys" / "tiago.yaml"),
    ),
}


def _spread(values: np.ndarray) -> np.ndarray:
    """The jackknife spread of leave-one-out estimates (first axis: the folds)."""
    n = values.shape[0]
    return np.sqrt((n - 1) / n * ((values - values.mean(axis=0)) ** 2).sum(axis=0))


def _prediction_std(cal, cov, meas) -> np.ndarray:
    """Standard deviation of each predicted position component from the covariance
    (finite-difference Jacobian of the prediction over the estimated parameters)."""
    idx = np.flatnonzero([s == "estimated" for s in cal.status])
    p0 = cal.params.copy()
    base = cal.predict(meas).raw_position
    J = np.empty((*base.shape, idx.size))
    try:
        for j, i in enumerate(idx):
            h = 1e-7 * max(1.0, abs(p0[i]))
            cal.params = p0.copy()
            cal.params[i] += h
            J[..., j] = (cal.predict(meas).raw_position - base) / h
    finally:
        cal.params = p0
    C = cov[np.ix_(idx, idx)]
    return np.sqrt(np.einsum("nck,kl,ncl->nc", J, C, J))


def _ratios(robot, meas, model):
    """Reported std / leave-one-pose-out spread: the median over the joint parameters the
    data determine, over the prior-dominated ones, and over the predicted positions of
    every row."""
    res = calibrate(robot, meas, model)
    cal = res.calibrated
    folds = make_folds(meas, len({tuple(np.round(q, 9)) for q in meas.q_ctrl})).test
    th, pred = [], []
    for t in folds:
        keep = np.ones(meas.n, bool)
        keep[t] = False
        fold = calibrate(robot, meas.subset(keep), model).calibrated
        th.append(fold.params)
        pred.append(fold.predict(meas).raw_position)
    spread = _spread(np.array(th))
    group = np.array([sp.group for sp in cal.model.layout.specs])
    est = np.array([s == "estimated" for s in cal.status])
    held = np.isin(
        cal.layout.names,
        [n for d in res.diagnostics_with("prior_dominated") for n in d.parameters],
    )
    use = est & ~np.isin(group, ["base", "cam"]) & (spread > 0)
    r = cal.std / np.where(spread > 0, spread, 1.0)
    pr = _prediction_std(cal, res.covariance, meas) / _spread(np.array(pred))
    return (
        median(r[use & ~held]),
        median(r[use & held]) if np.any(use & held) else np.nan,
        median(pr.ravel()),
    )


def test_std_covers_errors_shared_by_the_rows_of_a_pose():
    """Twin, 40 poses seen as 3 rows each (markers at one point) with an error common to
    the pose (40 um, an effect the model lacks) and 5 um of independent noise: over 16
    data sets the estimates scatter by what the reported standard deviations say
    (median ratio within 1.5x); the row-by-row covariance alone says about 1/sqrt(3)."""
    e = experiment2(7, tracker=LaserTracker(1e-6, 0.0))
    robot = e.truth.robot
    base = e.test.subset(np.arange(0, 40 * 97, 97))
    est, std = [], []
    for seed in range(16):
        rng = np.random.default_rng(seed)
        common = rng.normal(0, 40e-6, (40, 3))
        p = np.repeat(base.p + common, 3, axis=0) + rng.normal(0, 5e-6, (120, 3))
        meas = Measurements("point", np.repeat(base.q_ctrl, 3, axis=0), p)
        cal = calibrate(robot, meas, "kinematic").calibrated
        est.append(cal.params)
        std.append(cal.std)
    est, std = np.array(est), np.array(std)
    group = np.array([sp.group for sp in cal.model.layout.specs])
    use = np.all(np.isfinite(std), axis=0) & (group != "base")
    r = median(np.median(std[:, use], axis=0) / est[:, use].std(axis=0, ddof=1))
    assert 1 / 1.5 <= r <= 1.5, r


def test_ur10e_kinematic_std_follows_the_leave_one_out_spread():
    """23 poses; the evidence narrows the joint-geometry priors to 0.1 / 0.3 and holds
    14 of 16 joint parameters (std 2.2x the spread when they were counted): the two the
    data determine 1.22x, the predicted positions 1.16x; the prior-held ones keep the
    prior's width, above the spread (3.1x)."""
    robot = load_robot("ur10e")
    meas = read_measurements(REAL / "ur10_mocap.csv", robot, check=False)
    data, held, pred = _ratios(robot, meas, "kinematic")
    assert 1 / 1.5 <= data <= 1.5, data
    assert 1 / 1.5 <= pred <= 1.5, pred
    assert held > 1.5, held  # what the prior holds, the refits cannot show


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "model"),
    [("tiago", "kinematic"), ("tiago", "full"), ("fr3", "kinematic"), ("fr3", "full")],
)
def test_std_follows_the_leave_one_out_spread(name, model):
    """TIAGo: 34 poses, 3 markers each, 0.39 of the spread with the row-by-row
    covariance; now parameters 0.97 (kinematic) / 0.98 (full), predictions 1.02 / 1.01
    (kinematic 3.3 when the widening scaled each parameter alone and so kept
    correlations the jackknife does not have). FR3: 1.16 / 1.10, predictions 1.18 /
    1.21."""
    f, rb = REAL_SETS[name]
    robot = load_robot(rb)
    meas = read_measurements(REAL / f, robot, check=False)
    data, _, pred = _ratios(robot, meas, model)
    assert 1 / 1.5 <= data <= 1.5, data
    assert 1 / 1.5 <= pred <= 1.5, pred


@pytest.mark.slow
def test_prior_dominated_std_is_not_overconfident_on_the_twin():
    """What to report for a parameter its prior holds: on the Monte-Carlo twin (8 noise
    draws, 100 tracker poses, full model) the prior-dominated parameters' reported std
    (their posterior's, about the prior's width) covers the truth conservatively (94.5 %
    within one std, all within two), the others near the nominal rates (80 % / 98 %).
    Their spread over left-out refits, which the real-set ratio compares with, would
    have covered 80 % / 94.5 % here, but it only sees the data's part: where the truth
    departs from the prior mean the shrinkage does not show in it."""
    from kinecal.simulation import parameter_recovery

    held_z, data_z = [], []
    for seed in range(8):
        e = experiment2(100 + seed, tracker=LaserTracker(5e-6, 0.0), n_side=5)
        res = calibrate(e.truth.robot, e.train, "full")
        rec = parameter_recovery(res, e.truth, e.train)
        held = {
            n for d in res.diagnostics_with("prior_dominated") for n in d.parameters
        }
        m = np.array([n in held for n in rec.names])
        held_z.append(np.asarray(rec.z)[m])
        data_z.append(np.asarray(rec.z)[~m])
    zh, zd = np.abs(np.concatenate(held_z)), np.abs(np.concatenate(data_z))
    assert zh.size > 50 and zd.size > 100
    assert np.mean(zh <= 1.0) >= 0.68 and np.mean(zh <= 2.0) >= 0.95
    assert 0.6 < np.mean(zd <= 1.0) < 0.9 and np.mean(zd <= 2.0) > 0.9
