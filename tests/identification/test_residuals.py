"""Whitened residuals and their Jacobian for every measurement kind, against finite
differences (the rotation part of pose data goes through the SO(3) log)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal.identification import Measurements, Weights, residuals
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import load_robot
from tests.helpers import assert_jacobian_matches_fd

ROBOT = load_robot("fanuc-lrmate200id")


def _data(kind, rng, n=12):
    lim = ROBOT.limits
    q = rng.uniform(lim[:, 0] * 0.6, lim[:, 1] * 0.6, size=(n, 6))
    p = rng.normal(size=(n, 3)) * 0.3
    if kind == "pose":
        R = Rotation.from_rotvec(rng.normal(size=(n, 3))).as_matrix()
        return Measurements(
            "pose", q, p, R_user_cam=R, sigma=rng.uniform(1, 2, n) * 1e-5
        )
    if kind == "sensor":
        targets = rng.normal(size=(3, 3)) * 0.2
        return Measurements(
            "sensor",
            q,
            p * 0.1,
            target_index=rng.integers(0, 3, n),
            targets=targets,
            target_labels=("a", "b", "c"),
        )
    return Measurements("point", q, p)


@pytest.mark.parametrize("kind", ["point", "pose", "sensor"])
def test_residual_jacobian_matches_finite_differences(kind, rng):
    meas = _data(kind, rng)
    cam_rotation = kind != "point"
    model = CalibrationModel(ROBOT, ModelSpec.preset("full", cam_rotation=cam_rotation))
    x = model.nominal + rng.normal(size=model.size) * model.layout.scales
    x[model.layout.group_indices("load")] = rng.normal(size=6) * 1e-3
    x[model.layout.group_indices("link")] = [0.4, 1.5]
    w = Weights.default(meas)
    if kind == "pose":
        w = Weights(w.sigma, rng.uniform(1, 3, meas.n) * 1e-4)
    blk = residuals(model, x, meas, w, jacobian=True)
    assert blk.J is not None and blk.J.shape == (*blk.r.shape, model.size)

    def f(z):
        return residuals(model, z, meas, w).r

    # Scaled parameters so that millimetres and radians weigh alike in the check.
    s = model.layout.scales
    assert_jacobian_matches_fd(
        blk.J * s, lambda u: f(x + (u - 1.0) * s), np.ones(model.size), rtol=1e-5
    )
