"""Issue 32 (4): the solver and the model's inputs validate their arguments at the
entry (scipy-style): a ValueError naming the argument and the shapes, not a solver that
"converges" on mismatched arrays, a NaN start that ends as "stalled", or numpy's reshape
message."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.identification._lm import solve_lm
from kinecal.models import ModelInputs


def _linear(A, b):
    def fun(x, jac):
        r = (A @ x - b)[:, None]
        return r, (A[:, None, :] if jac else None)

    return fun


A = np.arange(12.0).reshape(6, 2) % 5 + np.eye(6, 2)
B = np.ones(6)


def test_solve_lm_solves_a_valid_problem():
    res = solve_lm(_linear(A, B), np.zeros(2), np.ones(2, bool), np.ones(2))
    assert res.success
    assert np.allclose(res.x, np.linalg.lstsq(A, B, rcond=None)[0], atol=1e-8)


@pytest.mark.parametrize(
    ("x0", "free", "scales", "needles"),
    [
        (np.zeros(2), np.ones(3, bool), np.ones(2), ["free", "(2,)", "(3,)"]),
        (np.zeros(2), np.ones(2, bool), np.ones(4), ["scales", "(2,)", "(4,)"]),
        (np.zeros((2, 1)), np.ones(2, bool), np.ones(2), ["x0", "vector", "(2, 1)"]),
        (np.zeros(2), np.ones(2), np.ones(2), ["free", "booleans", "float64"]),
        (np.array([0, np.nan]), np.ones(2, bool), np.ones(2), ["x0", "finite"]),
        (np.zeros(2), np.ones(2, bool), np.array([1, 0.0]), ["scales", "> 0"]),
    ],
)
def test_solve_lm_refuses_mismatched_arguments(x0, free, scales, needles):
    with pytest.raises(ValueError) as e:
        solve_lm(_linear(A, B), x0, free, scales)
    for n in needles:
        assert n in str(e.value), str(e.value)


def test_solve_lm_refuses_nan_residuals_at_the_start():
    b = B.copy()
    b[3] = np.nan
    with pytest.raises(ValueError, match=r"residuals at x0 are not finite \(1 of 6"):
        solve_lm(_linear(A, b), np.zeros(2), np.ones(2, bool), np.ones(2))


def test_solve_lm_refuses_a_jacobian_of_the_wrong_shape():
    def fun(x, jac):
        return (A @ x - B)[:, None], (A[:4, None, :] if jac else None)

    with pytest.raises(ValueError, match=r"Jacobian at x0 must have shape \(6, 1, 2\)"):
        solve_lm(fun, np.zeros(2), np.ones(2, bool), np.ones(2))


@pytest.mark.parametrize(
    ("kwargs", "needles"),
    [
        ({"set_index": [0, 0]}, ["set_index", "(4,)", "(2,)"]),
        ({"marker_index": np.zeros(5, int)}, ["marker_index", "(4,)", "(5,)"]),
        ({"p_cam": np.zeros((4, 2))}, ["p_cam", "(4, 3)", "(4, 2)"]),
        ({"load_scale": np.ones(3)}, ["load_scale", "(4,)", "(3,)"]),
        ({"set_index": [0, 0.5, 0, 0]}, ["set_index", "integer"]),
    ],
)
def test_model_inputs_name_the_argument_and_the_shapes(kwargs, needles):
    with pytest.raises(DataError) as e:
        ModelInputs.make(np.zeros((4, 6)), **kwargs)
    for n in ["ModelInputs.make", *needles]:
        assert n in str(e.value), str(e.value)


def test_model_inputs_refuse_a_3d_q():
    with pytest.raises(DataError, match=r"q_ctrl must be \(N, n\).*\(2, 3, 4\)"):
        ModelInputs.make(np.zeros((2, 3, 4)))


def test_model_inputs_defaults():
    m = ModelInputs.make(np.zeros((3, 6)), set_index=[0, 1, 0])
    assert m.set_index.dtype == np.intp and m.p_cam.shape == (3, 3)
    assert (m.load_scale == 1).all()
