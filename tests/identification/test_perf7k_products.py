"""Issue 36: the products of the normal equations of one held Jacobian are formed once.

The stages read the normal equations of a Jacobian several times at one point (the
solver's last iterate, the prior adaptation, the evidence, the uncertainty, the next
stage's lifted start): the products of an earlier call on the same arrays serve, a span
inside theirs too; other residuals, other row weights or another array are computed
again. The numbers are those of a fresh product.
"""

from __future__ import annotations

import numpy as np
import pytest

import kinecal.identification._normal as nm
from kinecal.identification import calibrate, normal_equations
from kinecal.identification._normal import normal_of
from kinecal.measurement._residuals import ResidualBlock
from kinecal.models import _kernel
from tests.conftest import require_compiled_kernel


def _model_layout(rng: np.random.Generator, N: int, c: int, P: int) -> np.ndarray:
    return np.ascontiguousarray(rng.normal(size=(P, c, N))).transpose(2, 1, 0)


@pytest.fixture
def counted(monkeypatch):
    """The number of products formed (by the compiled kernel), with an empty store."""
    require_compiled_kernel()
    if not getattr(_kernel._ckernel, "GRAM", 0):
        pytest.skip("the compiled products need AVX (GCC or Clang on x86)")
    calls = {"n": 0}
    gram = _kernel.gram

    def counting_gram(*a):
        calls["n"] += 1
        return gram(*a)

    monkeypatch.setattr(nm._kernel, "gram", counting_gram)
    monkeypatch.setattr(nm, "_kept", [])
    return calls


def _fresh(r, J, cols, scales, w=None):
    X = J[:, :, cols] * scales
    if w is not None:
        X = X * w[:, None, None]
        r = r * w[:, None]
    Xm = X.reshape(-1, len(cols))
    return Xm.T @ Xm, Xm.T @ r.reshape(-1)


def test_the_products_of_one_jacobian_are_formed_once(rng, counted):
    N, c, P = 300, 3, 20
    J = _model_layout(rng, N, c, P)
    r = rng.normal(size=(N, c))
    cols, sc = np.arange(P), rng.uniform(0.5, 2.0, P)
    A1, g1 = normal_of(r, J, cols, sc)
    assert counted["n"] == 1
    A2, g2 = normal_of(r, J, cols, sc)
    sub = np.array([2, 3, 7, 11])
    A3, g3 = normal_of(r, J, sub, sc[sub])  # a span inside: its block
    assert counted["n"] == 1
    np.testing.assert_array_equal(A1, A2)
    np.testing.assert_array_equal(g1, g2)
    for A, g, cc, s in ((A1, g1, cols, sc), (A3, g3, sub, sc[sub])):
        A0, g0 = _fresh(r, J, cc, s)
        np.testing.assert_allclose(A, A0, rtol=0, atol=1e-12 * abs(A0).max())
        np.testing.assert_allclose(g, g0, rtol=0, atol=1e-12 * abs(g0).max())
    # The caller may change what it gets: the store does not change with it.
    A2 += 1.0
    np.testing.assert_array_equal(normal_of(r, J, cols, sc)[0], A1)


def test_other_arrays_are_computed_again(rng, counted):
    N, c, P = 200, 3, 10
    J = _model_layout(rng, N, c, P)
    r = rng.normal(size=(N, c))
    cols, sc = np.arange(P), np.ones(P)
    w = rng.uniform(0.2, 1.0, N)
    normal_of(r, J, cols, sc)
    r2 = r.copy()
    r2[0, 0] += 1.0
    _, g_r = normal_of(r2, J, cols, sc)  # other residuals
    A_w, g_w = normal_of(r, J, cols, sc, w)  # row weights
    J2 = _model_layout(rng, N, c, P)
    A_j, _ = normal_of(r, J2, cols, sc)  # another Jacobian
    assert counted["n"] == 4
    np.testing.assert_allclose(g_r, _fresh(r2, J, cols, sc)[1], rtol=1e-12, atol=1e-9)
    A0, g0 = _fresh(r, J, cols, sc, w)
    np.testing.assert_allclose(A_w, A0, rtol=0, atol=1e-12 * abs(A0).max())
    np.testing.assert_allclose(g_w, g0, rtol=0, atol=1e-12 * abs(g0).max())
    A0 = _fresh(r, J2, cols, sc)[0]
    np.testing.assert_allclose(A_j, A0, rtol=0, atol=1e-12 * abs(A0).max())
    # A span beyond the kept one (a Jacobian's first columns, then all of them).
    J3 = _model_layout(rng, N, c, 3 * P)
    normal_of(r, J3, np.arange(P), np.ones(P))
    normal_of(r, J3, np.arange(3 * P), np.ones(3 * P))
    assert counted["n"] == 6


def test_a_calibration_forms_fewer_products_than_it_reads(rng, counted, monkeypatch):
    """The stages of a calibration read the products at the points they share: each
    point's products formed once (on 300 twin poses: 17 reads, 11 products)."""
    from kinecal.workflows._simulate import simulate_paper_experiment

    reads = {"n": 0}
    inner = nm._normal_equations

    def counting(*a, **k):
        reads["n"] += 1
        return inner(*a, **k)

    monkeypatch.setattr(nm, "_normal_equations", counting)
    # ResidualBlock.normal with a held Jacobian: a product the store does not see.
    monkeypatch.setattr(
        ResidualBlock, "normal", lambda *a, **k: pytest.fail("not the shared products")
    )
    e = simulate_paper_experiment(2, n_train=300).experiment
    res = calibrate(e.truth.robot, e.train, "full")
    assert res.success
    assert counted["n"] <= reads["n"] - 6


def test_the_public_normal_equations_form_the_products_anew(rng, counted):
    """A library user's arrays may be written between two calls: the public function
    keeps nothing, and the fitter's store compares the residuals and weights it kept."""
    N, c, P = 200, 3, 10
    J = _model_layout(rng, N, c, P)
    r = rng.normal(size=(N, c))
    cols, sc = np.arange(P), np.ones(P)
    normal_equations(r, J, cols, sc)
    J *= 2.0  # written in place
    A, _ = normal_equations(r, J, cols, sc)
    assert counted["n"] == 2
    np.testing.assert_allclose(A, _fresh(r, J, cols, sc)[0], rtol=1e-12)
    assert nm._kept == []
    w = rng.uniform(0.2, 1.0, N)
    normal_of(r, J, cols, sc, w)
    r += 1.0  # the residuals written in place: not the kept ones
    w[:] = 1.0
    _, g = normal_of(r, J, cols, sc, w)
    assert counted["n"] == 4
    np.testing.assert_allclose(g, _fresh(r, J, cols, sc)[1], rtol=1e-12)
