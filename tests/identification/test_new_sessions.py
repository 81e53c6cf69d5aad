"""Issue 11 on the twin: 40 poses to calibrate, three later sessions (tracker moved each
time) to test with the user frames refitted. With priors, the full model is never worse
than the kinematic one; plain least squares on the full model overfits."""

from __future__ import annotations

import numpy as np

from kinecal.geometry import euler_zyx_to_matrix
from kinecal.identification import (
    CalibrationOptions,
    Measurements,
    calibrate,
    evaluate,
    registered_model,
)
from kinecal.simulation import LaserTracker, experiment2


def _later_sessions(test: Measurements, rng: np.random.Generator) -> Measurements:
    parts = np.array_split(rng.permutation(test.n), 3)
    p, q, s = [], [], []
    for k, idx in enumerate(parts):
        idx = np.sort(idx)
        R = euler_zyx_to_matrix(np.radians([20.0 * k + 5.0, 2.0 * k, -3.0]))
        t = np.array([0.3 * k, -0.2, 0.1 * k])
        p.append(test.p[idx] @ R.T + t)
        q.append(test.q_ctrl[idx])
        s.append(np.full(idx.size, k))
    return Measurements(
        "point",
        np.concatenate(q),
        np.concatenate(p),
        set_index=np.concatenate(s),
        set_labels=("s1", "s2", "s3"),
    )


def test_full_model_with_priors_on_later_sessions():
    e = experiment2(
        4,
        tracker=LaserTracker(10e-6, 5e-6),
        extras=("harmonics", "wrist", "masses"),
    )
    rng = np.random.default_rng(1)
    train = e.train.subset(np.sort(rng.choice(e.train.n, 40, replace=False)))
    test = _later_sessions(e.test.subset(np.arange(0, e.test.n, 3)), rng)
    robot = e.truth.robot

    def score(model, priors="all"):
        res = calibrate(robot, train, model, CalibrationOptions(priors=priors))
        return res, evaluate(res.calibrated, test, refit_user=True).metrics.rms_mm

    kin_res, kin = score("kinematic")
    _, full = score("full")
    _, full_ls = score("full", "none")
    nominal = evaluate(registered_model(kin_res), test, refit_user=True).metrics.rms_mm
    assert full <= 1.02 * kin, (full, kin)
    assert kin < 0.1 * nominal
    assert full < full_ls  # the priors are what keeps the full model from overfitting
