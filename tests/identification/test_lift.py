"""The lifted start of the compliance fit and the shared normal equations."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.identification import calibrate, residuals
from kinecal.identification._lift import _product_sigma, lifted_start
from kinecal.identification._lm import LMOptions, normal_equations, solve_lm
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import load_robot


@pytest.mark.parametrize("layout", ["parameter-major", "sample-major"])
def test_normal_equations_match_the_plain_products(layout, rng):
    N, c, P = 40, 3, 9
    J = rng.normal(size=(N, c, P))
    if layout == "parameter-major":  # the model's memory: (P, c, N), seen as (N, c, P)
        J = np.ascontiguousarray(J.transpose(2, 1, 0)).transpose(2, 1, 0)
    r = rng.normal(size=(N, c))
    cols = np.array([1, 2, 5, 7])
    scales = rng.uniform(0.5, 2.0, cols.size)
    w = rng.uniform(0.2, 1.0, N)
    for row_w in (None, w):
        ww = np.ones(N) if row_w is None else row_w
        Js = (J[:, :, cols] * ww[:, None, None]).reshape(-1, cols.size) * scales
        rs = (r * ww[:, None]).reshape(-1)
        A, g = normal_equations(r, J, cols, scales, row_w)
        np.testing.assert_allclose(A, Js.T @ Js, rtol=1e-12)
        np.testing.assert_allclose(g, Js.T @ rs, rtol=1e-12)


def test_product_sigma_is_the_standard_deviation_of_a_product(rng):
    m1, s1, m2, s2 = 0.3, 0.5, -2.0, 0.7
    x = rng.normal(m1, s1, 400_000) * rng.normal(m2, s2, 400_000)
    assert _product_sigma(m1, s1, m2, s2) == pytest.approx(np.std(x), rel=0.01)
    assert _product_sigma(0.0, np.inf, 1.0, 1.0) == np.inf


LINK_MODELS = {
    "full": "full",  # s2 shared by the shoulder and the elbow: 3 products
    "rfcm": "rfcm",  # three moments, one joint each
    "general": ModelSpec(  # mass and first moment of two bodies: 20 products
        ntm_joints=(1, 2, 3), load=True, link="general", link_bodies=(2, 3)
    ),
}


@pytest.fixture(scope="module", params=sorted(LINK_MODELS))
def valley(request, exp2_exact):
    """A model with link weight on 1500 experiment-2 poses (all seven tool orientations),
    started where stage 3 starts: the kinematic and transmission parameters have absorbed
    the link weight, lambda* = s = 0."""
    e = exp2_exact
    robot = e.truth.robot
    meas = e.test.subset(np.random.default_rng(0).permutation(e.test.n)[:1500])
    res = calibrate(robot, meas, LINK_MODELS[request.param])
    ntm = calibrate(robot, meas, "ntm")
    cm = res.model
    start = cm.layout.transfer(ntm.params, ntm.model.layout)
    free = res.identifiability.free
    inp = meas.model_inputs(res.calibrated.reference_payload_kg)

    def fun(x, jac, products=False):
        b = residuals(
            cm, x, meas, res.weights, inputs=inp, jacobian=jac, products=products
        )
        return b.r, b.J

    lm = LMOptions(max_iter=200, stol=1e-4)  # as calibrate runs it
    plain = solve_lm(fun, start, free, cm.layout.scales, lm, prior=res.prior)
    assert plain.success
    return cm, fun, start, free, res, plain, lm


def test_lifted_start_lands_next_to_the_optimum(valley):
    cm, fun, start, free, res, plain, lm = valley
    assert len(cm.link_products) in (3, 20)
    r, J = fun(start, True, products=True)
    x1 = lifted_start(cm, start, r, J, free, res.prior)
    # From the lifted start a warm LM converges in a few iterations, never to a higher
    # objective than plain LM from the same start reaches in many more: with rfcm's
    # one-joint moments plain LM settles in a poorer basin (objective +52 here).
    warm = solve_lm(
        fun, x1, free, cm.layout.scales, replace(lm, mu0=1e-6), prior=res.prior
    )
    assert warm.success and warm.n_iter <= 5 < plain.n_iter / 2, (
        warm.n_iter,
        plain.n_iter,
    )
    assert warm.cost <= plain.cost + 1e-3  # both stop within ~1 % of a sigma
    f = np.flatnonzero(free)
    off0 = np.abs(start - warm.x)[f] / res.std[f]
    off1 = np.abs(x1 - warm.x)[f] / res.std[f]
    assert off0.max() > 5.0  # the start is far off in the valley, the lift next to it
    assert off1.max() < 0.2, dict(zip(np.array(cm.layout.names)[f], off1.round(2)))


def test_calibration_stage_3_takes_a_few_iterations(valley):
    _, _, _, _, res, _, _ = valley
    stage3 = [s for s in res.stages if s.name.startswith("stage 3")]
    assert stage3 and all(s.success and s.iterations <= 6 for s in stage3), [
        (s.name, s.iterations) for s in stage3
    ]


def test_no_products_no_lift(rng):
    robot = load_robot("fanuc-lrmate200id")
    for spec in (
        ModelSpec.preset("ntm"),
        ModelSpec.preset("full", has_self_weight=False),
    ):
        cm = CalibrationModel(robot, spec)
        assert cm.link_products == []
        x = cm.nominal.copy()
        r, J = np.zeros((5, 3)), np.zeros((5, 3, cm.size))
        assert lifted_start(cm, x, r, J, np.ones(cm.size, bool), None) is x


def test_variable_projection_finds_the_minimum_of_the_bilinear_model(rng):
    """The manifold step (Eq. T-11) against a general minimiser of the same cost: the
    lifted quadratic model in ``(x[native], x[lam] x[s])`` plus Gaussian priors."""
    from scipy.optimize import minimize

    from kinecal.identification._lift import _project
    from kinecal.identification._lm import Prior

    P = 8
    native, s_idx = np.arange(6), np.array([6, 7])
    pairs = [(P + 0, 0, 6), (P + 1, 0, 7), (P + 2, 1, 7)]  # lam 0, 1; s 6, 7
    scales = rng.uniform(0.5, 2.0, P)
    x = rng.normal(size=P)
    sc_l = np.concatenate(
        [scales[native], [scales[lam] * scales[s] for _, lam, s in pairs]]
    )
    z0 = np.concatenate([x[native], [x[lam] * x[s] for _, lam, s in pairs]])
    B = rng.normal(size=(20, sc_l.size))
    A, g = B.T @ B, B.T @ rng.normal(size=20)
    # Priors on some parameters, always on the products' factors: without, the infimum
    # can lie at infinity (lambda* -> 0, s -> inf), as for a model without them.
    sigma = np.where(rng.uniform(size=P) < 0.5, rng.uniform(0.5, 3.0, P), np.inf)
    sigma[[0, 1, 6, 7]] = rng.uniform(0.5, 3.0, 4)
    pr = Prior(rng.normal(size=P), sigma)

    def cost(xx):
        zz = np.concatenate([xx[native], [xx[lam] * xx[s] for _, lam, s in pairs]])
        d = (zz - z0) / sc_l
        return 0.5 * d @ A @ d + d @ g + pr.cost(xx)

    x1 = x + 0.1 * scales * rng.normal(size=P)
    got = _project(x, x1, native, s_idx, pairs, scales, A, g, pr, 0.0)
    ref = minimize(
        lambda z: cost(x1 + scales * z),
        np.zeros(P),
        method="BFGS",
        options={"gtol": 1e-12, "maxiter": 10_000},
    )
    want = x1 + scales * ref.x
    assert cost(got) <= cost(want) + 1e-9 * abs(cost(want))
    np.testing.assert_allclose((got - want) / scales, 0.0, atol=1e-5)
