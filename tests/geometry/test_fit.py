"""Kabsch/Umeyama and AX = YB closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.geometry import (
    kabsch_umeyama,
    se3_exp,
    solve_axyb,
    transform_inv,
    transform_points,
)


def test_kabsch_recovers_transform_with_noise(rng):
    T = se3_exp(rng.normal(size=6))
    p = rng.uniform(-1, 1, size=(200, 3))
    q = transform_points(T, p) + rng.normal(size=p.shape) * 1e-6
    T_fit, scale = kabsch_umeyama(p, q)
    assert scale == 1.0
    np.testing.assert_allclose(T_fit, T, atol=1e-6)


def test_umeyama_scale_and_weights(rng):
    T = se3_exp(rng.normal(size=6))
    p = rng.uniform(-1, 1, size=(30, 3))
    q = transform_points(T, 2.5 * p)
    q_out = q.copy()
    q_out[0] += 10.0  # an outlier with zero weight must not matter
    w = np.ones(30)
    w[0] = 0.0
    T_fit, s = kabsch_umeyama(p, q_out, w, with_scale=True)
    assert s == pytest.approx(2.5, rel=1e-12)
    np.testing.assert_allclose(T_fit[:3, :3], T[:3, :3], atol=1e-12)


def test_kabsch_rejects_degenerate_input():
    with pytest.raises(ValueError, match="at least 3"):
        kabsch_umeyama(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.outer(np.arange(5.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="collinear"):
        kabsch_umeyama(line, line)


def test_axyb_exact_and_noisy(rng):
    X = se3_exp(rng.normal(size=6))
    Y = se3_exp(rng.normal(size=6) * 2)
    B = se3_exp(rng.normal(size=(20, 6)))
    A = Y @ B @ transform_inv(X)
    Xs, Ys = solve_axyb(A, B)
    np.testing.assert_allclose(Xs, X, atol=1e-10)
    np.testing.assert_allclose(Ys, Y, atol=1e-10)
    An = A @ se3_exp(rng.normal(size=(20, 6)) * 1e-4)
    Xn, _ = solve_axyb(An, B)
    np.testing.assert_allclose(Xn[:3, :3], X[:3, :3], atol=1e-3)


def test_axyb_rejects_pure_translation(rng):
    B = se3_exp(np.concatenate([rng.normal(size=(5, 3)), np.zeros((5, 3))], axis=1))
    with pytest.raises(ValueError, match="too little motion"):
        solve_axyb(B, B)
