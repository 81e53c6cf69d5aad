"""Slow studies (``make test-slow``): Monte-Carlo coverage and the full-size experiment.

A single calibration can pass a 3-sigma check by luck; over many noise draws the reported
standard deviations must be *calibrated*: about 68 % of the z-scores within 1 and about
95 % within 2. And the full experiment 2 (7000 poses) must run through the whole pipeline.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import calibrate, evaluate
from kinecal.simulation import LaserTracker, experiment2, parameter_recovery

pytestmark = pytest.mark.slow


def test_reported_std_are_calibrated_over_noise_draws():
    z_all = []
    for seed in range(8):
        e = experiment2(100 + seed, tracker=LaserTracker(5e-6, 0.0), n_side=5)
        res = calibrate(e.truth.robot, e.train, "full")
        assert res.success
        z_all.append(parameter_recovery(res, e.truth, e.train).z)
    z = np.concatenate(z_all)
    within1 = np.mean(np.abs(z) <= 1.0)
    within2 = np.mean(np.abs(z) <= 2.0)
    # Gaussian: 0.68 and 0.95. The MAP priors make the reported std conservative here
    # (0.80-0.82 within one std): the evidence scale of the link priors is chosen at the
    # stage-3 solution, and where the link moments' split against the compliances is
    # flat one seed's choice flips between 0.01 and 3 with the start of that stage
    # (0.798 before the lifted start's variable projection, 0.821 after). A std twice
    # too large would put 0.95 within one std; one too small, under 0.55.
    assert 0.55 < within1 < 0.85, within1
    assert 0.88 < within2 < 0.99, within2


def test_full_experiment_two_with_all_poses():
    e = experiment2(7, tracker=LaserTracker(5e-6, 0.0))
    big = e.test  # ~6900 poses: calibrate on all of them, score on the 100 others
    res = calibrate(e.truth.robot, big, "full")
    assert res.success
    assert big.n > 6500
    rms = evaluate(res.calibrated, e.train).metrics.rms_mm
    assert rms < 1.2 * 5e-3 * np.sqrt(3)  # at the tracker's noise floor
