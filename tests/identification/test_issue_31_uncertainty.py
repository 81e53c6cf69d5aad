"""Issue 31 point 5: reported standard deviations against the spread of the estimates over
left-out poses (calibrating again without each pose), on real data. The covariance of
independent rows misses residuals that move together (three markers per TIAGo pose, an
effect the model lacks): the reported standard deviation is never below the jackknife
over left-out poses (one Gauss-Newton step on the downdated normal equations each)."""

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


def _ratio(robot, meas, model):
    """Median over the estimated joint parameters of reported std / leave-one-pose-out
    spread (jackknife scaling)."""
    res = calibrate(robot, meas, model)
    cal = res.calibrated
    folds = make_folds(meas, len({tuple(np.round(q, 9)) for q in meas.q_ctrl})).test
    th = []
    for t in folds:
        keep = np.ones(meas.n, bool)
        keep[t] = False
        th.append(calibrate(robot, meas.subset(keep), model).calibrated.params)
    th = np.array(th)
    n = len(folds)
    spread = np.sqrt((n - 1) / n * ((th - th.mean(axis=0)) ** 2).sum(axis=0))
    group = np.array([sp.group for sp in cal.model.layout.specs])
    est = np.array([s == "estimated" for s in cal.status])
    use = est & ~np.isin(group, ["base", "cam"]) & (spread > 0)
    return median(cal.std[use] / spread[use])


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


@pytest.mark.slow
def test_tiago_std_follows_the_leave_one_out_spread():
    """34 poses, 3 markers each: 0.39 of the spread before (row-by-row covariance);
    within 1.5x now."""
    robot = load_robot(
        str(ROOT / "examples" / "data" / "tiago_figaroh_qualisys" / "tiago.yaml")
    )
    meas = read_measurements(REAL / "tiago_mocap.csv", robot, check=False)
    r = _ratio(robot, meas, "kinematic")
    assert 1 / 1.5 <= r <= 1.5, r


@pytest.mark.slow
def test_fr3_std_follows_the_leave_one_out_spread():
    robot = load_robot("franka-fr3")
    meas = read_measurements(REAL / "fr3_session_a.csv", robot, check=False)
    for model in ("kinematic", "full"):
        r = _ratio(robot, meas, model)
        assert 1 / 1.5 <= r <= 1.5, (model, r)
