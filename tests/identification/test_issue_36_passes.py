"""Issue 36, point 3: fewer passes over the data, the same numbers.

The rejection's robust probe and the nominal check start from the calibration's own state
after registration and the identifiability analysis (neither depends on the loss or the
priors) instead of computing it again.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from kinecal.identification import CalibrationOptions, calibrate, default_stages
from kinecal.identification._nominal_check import _without_geometry_priors
from kinecal.identification._problem import Problem, run_stages
from kinecal.identification._robust import RobustRejection, row_z
from kinecal.identification._stages import run_shared
from kinecal.models import pass_counts
from tests.helpers import exact_pose_data


def _jacobians(fn):
    before = pass_counts()["jacobian"]
    out = fn()
    return out, pass_counts()["jacobian"] - before


def test_the_state_after_identification_is_kept(exp2_exact):
    e = exp2_exact
    res = calibrate(e.truth.robot, e.train, "full")
    ident = res.identified
    assert ident is not None and ident.active is None
    np.testing.assert_array_equal(ident.x, res.registered)
    np.testing.assert_array_equal(ident.free, res.identifiability.free)
    assert ident.prior is None  # before the priors


def test_the_nominal_check_fit_from_the_shared_state_is_the_same(exp2_exact):
    """The fit without geometry priors from the shared state: the same numbers to the
    last bit as from the nominal start, with fewer Jacobian passes."""
    e = exp2_exact
    robot, meas, opts = e.truth.robot, e.train, CalibrationOptions()
    res = calibrate(robot, meas, "full", opts)
    shared, n_shared = _jacobians(
        lambda: _without_geometry_priors(res, robot, meas, opts)
    )
    alone = dataclasses.replace(res, identified=None)
    fresh, n_fresh = _jacobians(
        lambda: _without_geometry_priors(alone, robot, meas, opts)
    )
    np.testing.assert_array_equal(shared.params, fresh.params)
    np.testing.assert_array_equal(shared.std, fresh.std)
    np.testing.assert_array_equal(shared.registered, fresh.registered)
    assert shared.sigma0 == fresh.sigma0
    assert shared.calibrated.status == fresh.calibrated.status
    assert [d.code for d in shared.diagnostics] == [d.code for d in fresh.diagnostics]
    assert n_shared < n_fresh
    # From the calibration's solution: the same fit on clean data (its s0 within 1e-4),
    # in at most 2 Jacobian passes with the calibration's workspace (its solution's
    # Jacobian kept there), 3 without, the same numbers.
    screen, n_screen = _jacobians(
        lambda: _without_geometry_priors(res, robot, meas, opts, from_fit=True)
    )
    assert screen is not None and n_screen <= 2
    assert abs(screen.sigma0 / fresh.sigma0 - 1) < 1e-4
    # s0 alone: the screen's standard deviations are never read (no covariance formed)
    assert np.isnan(screen.std).all() and not np.isnan(fresh.std).all()
    bare = dataclasses.replace(res, workspace=None)
    again, n_again = _jacobians(
        lambda: _without_geometry_priors(bare, robot, meas, opts, from_fit=True)
    )
    assert again is not None and n_screen < n_again <= 3
    np.testing.assert_array_equal(again.params, screen.params)
    assert again.sigma0 == screen.sigma0
    assert _without_geometry_priors(alone, robot, meas, opts, from_fit=True) is None


def test_the_nominal_check_screens_from_the_fit_and_reports_from_nominal():
    """The UR10e poses on the CB table: the screen from the fit sees the priors holding
    the fit back, so the findings come from the fit from nominal, with its numbers (the
    fit from the solution ends in another minimum there); on the right table the screen
    answers alone."""
    from pathlib import Path

    from kinecal.identification import nominal_check
    from kinecal.io import read_measurements
    from kinecal.robot import load_robot

    data = Path(__file__).resolve().parents[1] / "data" / "real" / "ur10_mocap.csv"
    robot = load_robot("ur10")
    meas = read_measurements(data, load_robot("ur10e"))
    res = calibrate(robot, meas, "full")
    found, n = _jacobians(lambda: nominal_check(res, robot, meas))
    nominal = _without_geometry_priors(
        dataclasses.replace(res, identified=None), robot, meas, CalibrationOptions()
    )
    assert nominal is not None
    held = next(d for d in found if d.code == "priors_held")
    assert f"{res.sigma0 / nominal.sigma0:.2f}x" in held.message
    assert f"RMS {nominal.metrics_after.rms_mm:.4g} mm" in held.message
    right = load_robot("ur10e")
    res_e = calibrate(right, meas, "full")
    found_e, n_e = _jacobians(lambda: nominal_check(res_e, right, meas))
    assert not [d for d in found_e if d.code in ("priors_held", "nominal_mismatch")]
    assert n_e < n


def test_the_rejection_probe_from_the_shared_state_is_the_same(exp2_exact):
    """The robust kinematic probe started from the fit's identified state gives the
    same row z as the probe run from the nominal start."""
    e = exp2_exact
    problem = Problem.make(e.truth.robot, e.train, "full", CalibrationOptions())
    stages = default_stages()
    state = run_stages(problem, problem.start(), stages[:2])
    rejection = next(s for s in stages if isinstance(s, RobustRejection))
    rob = problem.with_options(dataclasses.replace(problem.options, loss="huber"))
    shared, n_shared = _jacobians(lambda: run_shared(rob, state, rejection.probe))
    fresh, n_fresh = _jacobians(
        lambda: run_shared(rob, state.but(identified=None), rejection.probe)
    )
    np.testing.assert_array_equal(shared.x, fresh.x)
    np.testing.assert_array_equal(row_z(rob, shared)[0], row_z(rob, fresh)[0])
    # (Registration's Jacobian is kept, and the analysis takes it: no pass of its own.)
    assert n_shared <= n_fresh


def _cache_case(e, kind):
    """An evaluation cache of ``e``'s training data (positions, or poses), its model
    and a point off the nominal."""
    from kinecal.identification._problem import EvaluationCache
    from kinecal.measurement._residuals import Weights
    from kinecal.models import CalibrationModel, ModelSpec

    meas = exact_pose_data(e.truth, e.train) if kind == "pose" else e.train
    cm = CalibrationModel(e.truth.robot, ModelSpec.preset("full"))
    x = cm.nominal + 1e-4 * np.random.default_rng(3).standard_normal(cm.size)
    cache = EvaluationCache(meas, meas.model_inputs())
    return cache, cm, x, Weights.default(meas), meas


@pytest.mark.parametrize("kind", ["position", "pose"])
def test_new_weights_at_a_kept_point_take_no_jacobian_pass(exp2_exact, kind):
    """The noise re-estimation changes only the weights: the Jacobian kept at that
    point is rescaled row by row (no pass), and equals a fresh evaluation."""
    from kinecal.measurement._residuals import Weights, residuals

    cache, cm, x, w, meas = _cache_case(exp2_exact, kind)
    first = cache(cm, x, w, jacobian=True, products=True)
    scale = np.linspace(0.5, 2.0, meas.n)
    w2 = Weights(w.sigma * scale, None if w.sigma_rot is None else w.sigma_rot / scale)
    blk, n = _jacobians(lambda: cache(cm, x, w2, jacobian=True, products=True))
    assert n == 0
    fresh = residuals(
        cm, x, meas, w2, inputs=meas.model_inputs(), jacobian=True, products=True
    )
    assert blk.J is not None and fresh.J is not None and first.J is not None
    assert blk.J.shape == fresh.J.shape and blk.J is not first.J
    np.testing.assert_array_equal(blk.r, fresh.r)
    np.testing.assert_allclose(blk.J, fresh.J, rtol=1e-14, atol=0.0)
    assert cache(cm, x, w2, jacobian=True) is blk  # kept under the new weights


def test_the_calibration_and_its_nominal_check_take_few_jacobian_passes(exp2_exact):
    """Issue 36, point 3: the stages share their Jacobians (the diagnosis reads the
    uncertainty's, the rejection's probe continues the priors' pre-fit instead of
    repeating it, the nominal check starts from the solution's, which the result
    keeps): 11 + 2
    passes on these 100 poses (15 + 3 before; 19 -> 13 for the whole command on 2000
    twin poses)."""
    from kinecal.identification import nominal_check

    e = exp2_exact
    robot, meas = e.truth.robot, e.train
    res, n_fit = _jacobians(lambda: calibrate(robot, meas, "full"))
    _, n_check = _jacobians(lambda: nominal_check(res, robot, meas))
    assert n_fit <= 11 and n_check <= 2


def test_the_probe_continues_the_priors_pre_fit_to_the_same_numbers(exp2_exact):
    """Stage 1 without priors from the identified state goes on from the priors'
    pre-fit (the same iterates, stopped at the smaller tolerance): the same x and row z
    as the probe run afresh, with fewer passes."""
    from kinecal.identification._solve import SolverRun

    e = exp2_exact
    res = calibrate(e.truth.robot, e.train, "full")
    ident = res.identified
    assert ident is not None and isinstance(ident.prefit, SolverRun)
    problem = Problem.make(e.truth.robot, e.train, "full", CalibrationOptions())
    rejection = next(s for s in default_stages() if isinstance(s, RobustRejection))
    rob = problem.with_options(dataclasses.replace(problem.options, loss="huber"))
    on = ident.but(identified=ident)  # run_shared starts from its identified state
    off = ident.but(identified=ident.but(prefit=None))
    goes_on, n_on = _jacobians(lambda: run_shared(rob, on, rejection.probe))
    afresh, n_afresh = _jacobians(lambda: run_shared(rob, off, rejection.probe))
    np.testing.assert_array_equal(goes_on.x, afresh.x)
    np.testing.assert_array_equal(row_z(rob, goes_on)[0], row_z(rob, afresh)[0])
    assert n_on < n_afresh
