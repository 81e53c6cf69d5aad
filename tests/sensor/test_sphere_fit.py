"""Sphere fitting: exactness, noisy caps with outliers (issue 6), covariance."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.sensor import fit_sphere


def _cap(rng, n, c, R, half_angle_deg, noise):
    """Points on the cap of a sphere around +z... facing -z (what a camera above sees)."""
    cosmax = np.cos(np.radians(half_angle_deg))
    ct = rng.uniform(cosmax, 1.0, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    st = np.sqrt(1 - ct**2)
    d = np.column_stack([st * np.cos(phi), st * np.sin(phi), -ct])
    return c + d * (R + rng.normal(size=n) * noise)[:, None]


def test_exact_points_give_exact_sphere():
    rng = np.random.default_rng(0)
    c = np.array([0.01, -0.02, 0.14])
    f = fit_sphere(_cap(rng, 400, c, 0.015, 60, 0.0))
    np.testing.assert_allclose(f.center, c, atol=1e-12)
    assert f.radius == pytest.approx(0.015, abs=1e-12)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_cap_with_10um_noise_and_outliers_within_2um(seed):
    rng = np.random.default_rng(seed)
    c = np.array([0.003, 0.001, 0.140])
    R = 0.015001
    P = _cap(rng, 30_000, c, R, 70, 10e-6)
    bad = rng.choice(P.shape[0], 40, replace=False)
    P[bad] += rng.normal(size=(40, 3)) * 0.5e-3 + 0.3e-3  # a few dozen gross errors
    f = fit_sphere(P)
    assert np.linalg.norm(f.center - c) < 2e-6
    assert abs(f.radius - R) < 2e-6
    assert (f.n_outliers >= 35 and not f.inliers[bad].any()) or f.inliers[
        bad
    ].sum() <= 5
    assert 8e-6 < f.rms < 12e-6


def test_covariance_matches_monte_carlo():
    c = np.array([0.0, 0.0, 0.13])
    est = []
    cov = None
    for seed in range(200):
        rng = np.random.default_rng(100 + seed)
        f = fit_sphere(_cap(rng, 2000, c, 0.015, 50, 10e-6), outlier_k=None)
        est.append(f.center)
        cov = f.covariance
    emp = np.std(np.array(est), axis=0)
    assert cov is not None
    np.testing.assert_allclose(emp, np.sqrt(np.diag(cov))[:3], rtol=0.2)


def test_fixed_radius_and_errors():
    rng = np.random.default_rng(5)
    c = np.array([0.0, 0.01, 0.13])
    P = _cap(rng, 1000, c, 0.015, 40, 5e-6)
    f = fit_sphere(P, radius=0.015)
    assert f.covariance.shape == (3, 3) and f.radius == 0.015
    assert np.linalg.norm(f.center - c) < 2e-6
    with pytest.raises(DataError, match="at least"):
        fit_sphere(P[:5])
    P[3, 1] = np.nan
    with pytest.raises(DataError, match="point 3"):
        fit_sphere(P)
