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
    assert 0.55 < within1 < 0.80, within1
    assert 0.88 < within2 < 0.99, within2


def test_full_experiment_two_with_all_poses():
    e = experiment2(7, tracker=LaserTracker(5e-6, 0.0))
    big = e.test  # ~6900 poses: calibrate on all of them, score on the 100 others
    res = calibrate(e.truth.robot, big, "full")
    assert res.success
    assert big.n > 6500
    rms = evaluate(res.calibrated, e.train).metrics.rms_mm
    assert rms < 1.2 * 5e-3 * np.sqrt(3)  # at the tracker's noise floor
