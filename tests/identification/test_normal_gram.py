"""The compiled products of the normal equations (``_ckernel.gram``) against BLAS: the
same ``Jsᵀ Js`` and ``Jsᵀ r`` to rounding, at every edge of its blocks and tiles, and used
only where they serve."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import normal_equations
from kinecal.identification._normal import _products
from kinecal.models import _kernel
from tests.conftest import require_compiled_kernel


@pytest.fixture(autouse=True)
def _gram() -> None:
    require_compiled_kernel()
    if not getattr(_kernel._ckernel, "GRAM", 0):
        pytest.skip("the compiled products need AVX (GCC or Clang on x86)")


def _model_layout(rng: np.random.Generator, N: int, c: int, P: int) -> np.ndarray:
    """A (N, c, P) Jacobian in the model's parameter-major memory."""
    return np.ascontiguousarray(rng.normal(size=(P, c, N))).transpose(2, 1, 0)


# Poses around the 192 columns of a block (and its 4-column vectors), spans of odd and
# even width (the 2 x 4 tiles, the residual row after them), point and pose rows.
@pytest.mark.parametrize(
    ("N", "c", "P", "cols"),
    [
        (1, 3, 3, [0, 1, 2]),
        (5, 3, 9, [1, 2, 5, 7]),
        (191, 3, 12, list(range(12))),
        (192, 3, 7, [0, 6]),
        (193, 6, 10, [2, 3, 4, 5, 6, 7, 8]),
        (385, 3, 50, list(range(50))),
        (402, 3, 55, [0, *range(3, 52)]),
    ],
)
def test_the_compiled_products_equal_blas(N, c, P, cols, rng, monkeypatch):
    J = _model_layout(rng, N, c, P)
    r = rng.normal(size=(N, c))
    cols = np.array(cols)
    scales = rng.uniform(0.5, 2.0, cols.size)
    for w in (None, rng.uniform(0.2, 1.0, N)):
        lo, hi = int(cols.min()), int(cols.max()) + 1
        G = _kernel.gram(J, r, lo, hi, w)
        assert G is not None and G.shape == (hi - lo + 1, hi - lo + 1)
        A0, g0 = _products(r, J, lo, hi, w)
        k = hi - lo
        # Sums in another order: equal to rounding of the largest terms (entries that
        # cancel have no relative accuracy to compare).
        tol = 1e-13 * abs(A0).max()
        np.testing.assert_allclose(np.triu(G[:k, :k]), np.triu(A0), rtol=0, atol=tol)
        np.testing.assert_allclose(G[:k, k], g0, rtol=0, atol=1e-13 * abs(g0).max())
        assert not np.tril(G, -1).any()  # one triangle only
        A, g = normal_equations(r, J, cols, scales, w)
        monkeypatch.setenv("KINECAL_KERNEL", "numpy")  # the BLAS products
        A1, g1 = normal_equations(r, J, cols, scales, w)
        monkeypatch.delenv("KINECAL_KERNEL")
        np.testing.assert_allclose(A, A1, rtol=0, atol=1e-13 * abs(A1).max())
        np.testing.assert_allclose(g, g1, rtol=0, atol=1e-13 * abs(g1).max())
        np.testing.assert_array_equal(A, A.T)


def test_the_compiled_products_serve_the_model_memory_only(rng, monkeypatch):
    """A Jacobian in other memory (a sample-major array, a strided view), or the numpy
    code chosen, takes the BLAS products; the model's own takes the compiled ones."""
    N, c, P = 30, 3, 6
    J = _model_layout(rng, N, c, P)
    r = rng.normal(size=(N, c))
    assert _kernel.gram(J, r, 0, P, None) is not None
    assert _kernel.gram(np.ascontiguousarray(J), r, 0, P, None) is None
    assert _kernel.gram(J[::2], r[::2], 0, P, None) is None
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")
    assert _kernel.gram(J, r, 0, P, None) is None


def test_the_compiled_products_refuse_arrays_that_do_not_match(rng):
    ck = _kernel._ckernel
    Jt = rng.normal(size=(6, 3, 10))
    r = rng.normal(size=(10, 3))
    out = np.zeros((7, 7))
    with pytest.raises(ValueError, match="do not match"):
        ck.gram(Jt, r, np.empty(0), out, 3, 0, 7)  # beyond the parameters
    with pytest.raises(ValueError, match="do not match"):
        ck.gram(Jt, r, np.ones(9), out, 3, 0, 6)  # weights of other poses
    with pytest.raises(ValueError, match="do not match"):
        ck.gram(Jt, r, np.empty(0), np.zeros((6, 6)), 3, 0, 6)  # output too small
    ck.gram(Jt, r, np.empty(0), out, 3, 0, 6)
    X = np.concatenate([Jt.reshape(6, -1), r.T.reshape(1, -1)])
    ref = np.triu(X @ X.T)
    np.testing.assert_allclose(np.triu(out), ref, rtol=0, atol=1e-13 * abs(ref).max())
