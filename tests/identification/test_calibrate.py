"""Helpers of the calibration pipeline."""

from __future__ import annotations

import pytest
from scipy.special import chdtri

from kinecal.identification._robust import chi2_isf


@pytest.mark.parametrize("df", [1, 2, 3, 4, 5, 6, 9])
def test_chi2_quantile_matches_scipy(df):
    for p in (0.5, 0.05, 1e-3, 1e-6, 1e-12):
        assert chi2_isf(df, p) == pytest.approx(chdtri(df, p), rel=1e-10)


def test_chi2_quantile_rejects_bad_arguments():
    with pytest.raises(ValueError, match="0 < p < 1"):
        chi2_isf(3, 0.0)


def test_evaluations_are_reused_only_where_they_apply(exp2_exact):
    import numpy as np

    from kinecal.identification import EvaluationCache, Weights, residuals
    from kinecal.models import CalibrationModel, ModelSpec

    e = exp2_exact
    meas = e.train
    cm = CalibrationModel(e.truth.robot, ModelSpec.preset("full", cam_rotation=False))
    inputs = meas.model_inputs()
    ev = EvaluationCache(meas, inputs)
    w1, w2 = Weights.default(meas), Weights(np.full(meas.n, 2e-5))
    x = cm.nominal.copy()
    b = ev(cm, x, w1, jacobian=True)
    assert ev(cm, x.copy(), w1) is b  # a Jacobian block serves a plain request
    assert ev(cm, x, w1, jacobian=True, products=True) is not b  # more columns
    assert ev(cm, x, w2) is not b  # other weights, other whitening
    np.testing.assert_array_equal(ev.raw_position(cm, x, w1), b.raw_position)
    y = x.copy()
    y[0] += 1e-6
    fresh = residuals(cm, y, meas, w2, inputs=inputs, jacobian=True)
    got = ev(cm, y, w2, jacobian=True)
    np.testing.assert_array_equal(got.r, fresh.r)
    np.testing.assert_array_equal(got.J, fresh.J)
    for k in range(5):  # only the last few points are kept
        ev(cm, x + k * 1e-7, w1)
    assert ev(cm, y, w2) is not got


def test_a_jacobian_after_a_plain_evaluation_reuses_its_forward_kinematics(
    exp2_exact, monkeypatch, numpy_kernel
):
    """The LM's accepted trial point is evaluated plainly, then with its Jacobian: the
    second evaluation (with any weights) takes the first's forward state, and gives the
    fresh block exactly."""
    import numpy as np

    from kinecal.identification import EvaluationCache, Weights, residuals
    from kinecal.models import CalibrationModel, ModelSpec

    meas = exp2_exact.train
    cm = CalibrationModel(exp2_exact.truth.robot, ModelSpec.preset("full"))
    inputs = meas.model_inputs()
    ev = EvaluationCache(meas, inputs)
    w1, w2 = Weights.default(meas), Weights(np.full(meas.n, 2e-5))
    x = cm.nominal.copy()
    x[cm.layout.index("joint2.lambda")] = 1e-3
    calls = []
    real = CalibrationModel._forward
    monkeypatch.setattr(
        CalibrationModel, "_forward", lambda *a: calls.append(1) or real(*a)
    )
    ev(cm, x, w1)
    got = ev(cm, x, w2, jacobian=True, products=True)
    assert calls == [1]
    fresh = residuals(cm, x, meas, w2, inputs=inputs, jacobian=True, products=True)
    np.testing.assert_array_equal(got.r, fresh.r)
    np.testing.assert_array_equal(got.J, fresh.J)


def test_a_run_stopped_by_its_iteration_limit_names_where_it_still_drifts():
    """The remaining Gauss-Newton step of a max_iter run points along the parameter the
    poses hardly determine (one tiny curvature); the warning names it with its value."""
    import numpy as np

    from kinecal.identification._lm import LMResult
    from kinecal.identification._solve import _drift
    from kinecal.models import CalibrationModel, ModelSpec
    from kinecal.robot import load_robot

    cm = CalibrationModel(load_robot("fanuc-lrmate200id"), ModelSpec.preset("full"))
    free = np.ones(cm.size, bool)
    lam6 = cm.layout.index("joint6.lambda")
    A = np.diag(np.full(cm.size, 1e4))
    A[lam6, lam6] = 1e-2  # a valley along lambda6*
    g = np.full(cm.size, 1.0)
    x = cm.nominal.copy()
    x[lam6] = -0.037

    def result(status: str) -> LMResult:
        return LMResult(
            x, 1.0, 200, 400, False, status, "", A, g, np.ones(3), np.ones(3)
        )

    text, names = _drift(cm, result("max_iter"), free, "none")
    assert "drifts along joint6.lambda (now -0.037 rad/m)" in text
    assert names == ("joint6.lambda",)
    assert "--priors all" in text and "joint5" not in text
    assert "--priors" not in _drift(cm, result("max_iter"), free, "all")[0]
    assert _drift(cm, result("stalled"), free, "none") == ("", ())


def test_the_unconstrained_prefit_stops_early_on_a_compliant_robot(monkeypatch):
    """Compliances 10x the usual: the kinematic model cannot fit them and the stage-1
    pre-fit (no priors) used to crawl for 100 iterations. With its looser statistical
    stop it takes a few; through the noise estimate and the prior scales it feeds, the
    final estimate moves by at most 0.11 of its standard deviations here."""
    import numpy as np

    from kinecal.identification import _options, _priors
    from kinecal.identification import calibrate as calibrate_
    from kinecal.robot import load_robot
    from kinecal.simulation import LaserTracker, experiment2, random_truth

    robot = load_robot("fanuc-lrmate200id")
    truth = random_truth(robot, seed=5, compliance=3e-3)
    meas = experiment2(5, truth=truth, tracker=LaserTracker(5e-6, 0.0)).train
    fast = calibrate_(robot, meas, "full")
    pre = fast.stages[1]
    assert pre.name == "stage 1: kinematic (no priors)"
    assert pre.iterations <= 15 and pre.status == "stol", (pre.iterations, pre.status)
    monkeypatch.setattr(_priors, "STOL_PRE", _options.STOL)
    tight = calibrate_(robot, meas, "full")
    assert tight.stages[1].iterations >= 50  # the crawl this avoids
    est = fast.calibrated.status
    z = (fast.calibrated.params - tight.calibrated.params) / tight.calibrated.std
    z = z[[s == "estimated" for s in est]]
    assert np.abs(z).max() < 0.2, np.abs(z).max()


def test_parameters_left_without_a_prior_and_loosely_determined_are_named(exp2_exact):
    """Without priors, the warning names the estimated parameters whose standard
    deviation exceeds the prior --priors all would give them, with that ratio, largest
    first; the default priors leave nothing to name."""
    import re

    from kinecal.identification import CalibrationOptions, build_prior, calibrate

    robot, meas = exp2_exact.truth.robot, exp2_exact.train
    found = {}
    for priors in ("none", "compliance", "all"):
        res = calibrate(robot, meas, "full", CalibrationOptions(priors=priors))
        diags = res.diagnostics_with("loose_parameters")
        found[priors] = (res, [d.message for d in diags])
        if diags:  # the structured field names the same parameters as the message
            (d,) = diags
            assert (
                list(d.parameters)
                == re.findall(r"([\w.]+) \([\d.e+]+x\)", d.message)[:8]
                or len(d.parameters) > 8
            )
    assert found["all"][1] == []
    res, (text,) = found["none"]
    names = re.findall(r"([\w.]+) \(([\d.e+]+)x\)", text)
    assert names and any(n.startswith("link.") for n, _ in names)
    ratios = [float(r) for _, r in names]
    assert ratios == sorted(ratios, reverse=True) and min(ratios) > 1.0
    cal = res.calibrated
    plausible = build_prior(cal.model, cal.params, CalibrationOptions()).sigma
    first, ratio = names[0]
    k = cal.model.layout.index(first)
    assert float(ratio) == pytest.approx(cal.std[k] / plausible[k], rel=1e-2)
    # the compliance priors hold the link and load terms: only geometry is left to name
    _, (text_c,) = found["compliance"]
    named = re.findall(r"([\w.]+) \([\d.e+]+x\)", text_c)
    assert named and not any(n.startswith(("link.", "joint6.lambda")) for n in named)
