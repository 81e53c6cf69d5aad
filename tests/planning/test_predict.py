"""The predicted accuracy of a design against a Monte Carlo of the linear problem."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.planning import predict, predict_random
from tests.planning.test_criteria import synthetic_problem


def test_predicted_heldout_rms_matches_monte_carlo(rng):
    """Draw parameters from the prior, data with noise, the MAP estimate; the held-out
    error at the candidates (new noise plus prediction error) has the predicted RMS and
    the estimates the predicted standard deviations."""
    pb = synthetic_problem(rng, N=50, p=6)
    sigma = rng.uniform(0.5, 2.0, 50)
    pb.sigma = sigma
    pb.G = pb.F * sigma[:, None, None]  # prediction = unwhitened position rows
    pb._moment = None
    design = rng.choice(50, 8, replace=False)
    M = pb.information(design)
    pr = predict(pb, M, 8)
    Fd = pb.F[design].reshape(-1, pb.size)
    A = np.linalg.inv(M)
    draws = 4000
    z = rng.normal(size=(draws, pb.size)) / np.sqrt(pb.prior_precision)
    y = z @ Fd.T + rng.normal(size=(draws, Fd.shape[0]))
    z_hat = (y @ Fd) @ A  # MAP with prior mean 0
    err = np.einsum("nip,dp->dni", pb.G, z_hat - z)  # (draws, N, 3)
    err += rng.normal(size=err.shape) * sigma[None, :, None]
    ms = np.mean(np.sum(err**2, axis=2))  # equal weights
    assert np.sqrt(ms) == pytest.approx(pr.heldout_rms, rel=0.03)
    np.testing.assert_allclose(np.std(z_hat - z, axis=0), pr.std, rtol=0.06)
    assert pr.floor == pytest.approx(np.sqrt(3 * np.mean(sigma**2)))
    assert pr.ratio > 1.0


def test_random_plans_are_predicted_worse_than_a_chosen_one(rng):
    from kinecal.planning import select_poses

    pb = synthetic_problem(rng, N=200, p=8)
    sel = select_poses(pb, 6)
    best = predict(pb, pb.information(sel.index), 6)
    rand = predict_random(pb, 6, draws=30, seed=1)
    assert rand.heldout_rms.shape == (30,)
    assert best.heldout_rms < rand.heldout_rms.min()
    assert rand.ratio > best.ratio
    with pytest.raises(ValueError, match="n must be between 1 and 200; got 201"):
        predict_random(pb, 201)
