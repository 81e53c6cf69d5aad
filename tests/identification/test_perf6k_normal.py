"""The normal equations of a model's own Jacobian: the compiled products, which leave a
block's rows of zeros out (other user frames and markers, a frame's translation in its
other components), against BLAS's, on a model with every kind of term."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import normal_equations
from kinecal.identification._normal import _products
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec, _kernel
from kinecal.robot import load_robot
from tests.conftest import require_compiled_kernel

SPEC = ModelSpec(
    cam_rotation=True,
    ntm_joints=(1, 2, 3),
    ntm_order=2,
    load=True,
    link="paper",
    link_bodies=(2, 3),
    sets=("a", "b", "c"),
    markers=("m", "n"),
)


@pytest.fixture
def _gram() -> None:
    require_compiled_kernel()
    if not getattr(_kernel._ckernel, "GRAM", 0):
        pytest.skip("the compiled products need AVX (GCC or Clang on x86)")


def _case(n: int, rng: np.random.Generator):
    """A sensor model's Jacobian (N, 6, P) in the model's memory and residuals, the
    poses grouped by user frame (whole blocks of one frame) and markers mixed."""
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, SPEC)
    lim = np.clip(robot.limits, -3.0, 3.0)
    inputs = ModelInputs.make(
        rng.uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_joints)),
        set_index=np.sort(rng.integers(0, 3, n)),
        marker_index=rng.integers(0, 2, n),
        p_cam=rng.normal(size=(n, 3)) * 0.1,
        load_scale=rng.uniform(0.5, 1.5, n),
    )
    p = model.nominal.copy()
    for i, s in enumerate(model.layout.specs):
        if s.kind == "compliance":
            p[i] = 1e-4
        elif s.kind in ("moment", "ratio"):
            p[i] = 0.3
    out = model.evaluate(p, inputs, orientation=True, jacobian=True)
    assert out.J_p is not None and out.J_w is not None
    full = np.concatenate([out.J_p, out.J_w], axis=1)  # (N, 6, P)
    J = np.ascontiguousarray(full.transpose(2, 1, 0)).transpose(2, 1, 0)
    return J, rng.normal(size=(n, 6)) * 1e-4


def _close(a: np.ndarray, b: np.ndarray) -> None:
    """Equal to 1e-12 of the largest entry (sums in another order)."""
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * float(np.abs(b).max()))


@pytest.mark.usefixtures("_gram")
@pytest.mark.parametrize("weighted", [False, True])
def test_the_compiled_products_of_a_model_jacobian_equal_blas(weighted, rng):
    J, r = _case(1001, rng)
    P = J.shape[2]
    # The user frames' translations are zero in two components of three, and every
    # frame's columns on the poses of the other frames: blocks with rows of zeros.
    Jt = J.transpose(2, 1, 0)
    assert any(not Jt[i, q, :192].any() for i in range(P) for q in range(6))
    w = rng.uniform(0.2, 1.0, J.shape[0]) if weighted else None
    G = _kernel.gram(J, r, 0, P, w)
    assert G is not None
    A0, g0 = _products(r, J, 0, P, w)
    _close(np.triu(G[:P, :P]), np.triu(A0))
    _close(G[:P, P], g0)
    assert not np.tril(G, -1).any()


@pytest.mark.usefixtures("_gram")
@pytest.mark.parametrize(
    "pick", ["all", "a span", "some", "one"], ids=lambda s: s.replace(" ", "_")
)
def test_normal_equations_equal_blas_for_every_choice_of_columns(
    pick, rng, monkeypatch
):
    """Every column in order (no selection), a span, a sparse choice, one column."""
    J, r = _case(700, rng)
    P = J.shape[2]
    cols = {
        "all": np.arange(P),
        "a span": np.arange(5, P - 3),
        "some": np.array([0, 2, 3, 9, P - 1]),
        "one": np.array([4]),
    }[pick]
    scales = rng.uniform(0.5, 2.0, cols.size)
    w = rng.uniform(0.2, 1.0, J.shape[0])
    A, g = normal_equations(r, J, cols, scales, w)
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")  # BLAS's products
    A1, g1 = normal_equations(r, J, cols, scales, w)
    _close(A, A1)
    _close(g, g1)
    np.testing.assert_array_equal(A, A.T)
    # And by their definition.
    X = J[:, :, cols] * scales * w[:, None, None]
    Xm = X.reshape(-1, cols.size)
    _close(A, Xm.T @ Xm)
    _close(g, Xm.T @ (r * w[:, None]).reshape(-1))


@pytest.mark.usefixtures("_gram")
def test_a_block_of_zeros_and_zero_residuals_add_nothing(rng):
    """A column of zeros, a block of poses whose rows are all zero, and residuals of
    zero: the same as BLAS (zeros where they belong)."""
    N, c, P = 500, 3, 9
    Jt = rng.normal(size=(P, c, N))
    Jt[2] = 0.0  # a column of zeros
    Jt[:, :, 192:384] = 0.0  # a whole block
    J = np.ascontiguousarray(Jt).transpose(2, 1, 0)
    r = np.zeros((N, c))
    G = _kernel.gram(J, r, 0, P, None)
    assert G is not None
    A0, _ = _products(r, J, 0, P, None)
    _close(np.triu(G[:P, :P]), np.triu(A0))
    assert not G[2].any() and not G[:, 2].any() and not G[:, P].any()


@pytest.mark.parametrize("cols", [[0, 1, 2, 3, 4, 5], [1, 2, 3], [0, 2, 5], [3]])
def test_normal_equations_without_the_compiled_kernel(cols, rng, monkeypatch):
    """An installation without the compiled kernel: BLAS's products, every column of a
    span scaled in place or a choice of them, equal to the definition."""
    monkeypatch.setattr(_kernel, "_ckernel", None)
    N, c, P = 40, 3, 6
    J = np.ascontiguousarray(rng.normal(size=(P, c, N))).transpose(2, 1, 0)
    r = rng.normal(size=(N, c))
    sel = np.array(cols)
    scales = rng.uniform(0.5, 2.0, sel.size)
    assert _kernel.gram(J, r, 0, P, None) is None
    A, g = normal_equations(r, J, sel, scales)
    Xm = (J[:, :, sel] * scales).reshape(-1, sel.size)
    _close(A, Xm.T @ Xm)
    _close(g, Xm.T @ r.reshape(-1))
