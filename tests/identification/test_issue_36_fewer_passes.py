"""Issue 36, point 3: at most ~10 Jacobian passes for the whole calibration command.

* The nominal check's screen (the fit without geometry priors from the calibration's
  solution) reads only its ``s0``: it stops on the pre-fits' statistical tolerance and
  takes no Jacobian at its solution.
* Registration fits the frames from the flange frames (:class:`FrameFit`): its
  residuals and Jacobian columns are the model's own, without passes of the model.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import kinecal.identification._nominal_check as nc
from kinecal.identification import CalibrationOptions, calibrate, nominal_check
from kinecal.identification._frame_fit import FrameFit
from kinecal.identification._lm import LMOptions, solve_lm
from kinecal.identification._nominal_check import _without_geometry_priors
from kinecal.identification._problem import Problem
from kinecal.identification._stages import FullStage, Register
from kinecal.models import pass_counts
from tests.helpers import exact_pose_data


def _jacobians(fn):
    before = pass_counts()["jacobian"]
    out = fn()
    return out, pass_counts()["jacobian"] - before


@pytest.fixture(scope="module")
def twin500():
    """500 poses of the twin as ``kinecal simulate`` makes it (tracker noise, sigma)."""
    from kinecal.workflows._simulate import simulate_paper_experiment

    e = simulate_paper_experiment(2, n_train=500).experiment
    return e.truth.robot, e.train


def _curve_fit_case():
    """A small non-linear least squares (exponential decay with noise) whose run ends
    on the accepted step's decrease: ``fun`` counts its Jacobians."""
    t = np.linspace(0.0, 4.0, 60)
    y = 2.0 * np.exp(-0.7 * t) + 0.3 + 1e-3 * np.random.default_rng(0).normal(size=60)
    calls = {"jac": 0}

    def fun(x, jac):
        e = np.exp(-x[1] * t)
        r = (x[0] * e + x[2] - y)[:, None]
        if not jac:
            return r, None
        calls["jac"] += 1
        J = np.stack([e, -x[0] * t * e, np.ones_like(t)], axis=1)[:, None, :]
        return r, J

    return fun, calls


def test_a_run_without_its_final_jacobian_is_the_same_run():
    """``final_jacobian=False``: the same iterates, cost and status, one Jacobian
    fewer; its normal matrix, asked for, is the one the eager run formed."""
    opts = LMOptions(ftol=1e-6)
    runs = {}
    for final in (True, False):
        fun, calls = _curve_fit_case()
        res = solve_lm(
            fun,
            np.array([1.0, 1.0, 0.0]),
            np.ones(3, bool),
            np.ones(3),
            opts,
            final_jacobian=final,
        )
        runs[final] = (res, calls["jac"])
    (eager, n_eager), (lazy, n_lazy) = runs[True], runs[False]
    assert eager.status == lazy.status == "ftol"
    np.testing.assert_array_equal(eager.x, lazy.x)
    assert eager.cost == lazy.cost and eager.n_iter == lazy.n_iter
    assert n_lazy == n_eager - 1
    np.testing.assert_array_equal(lazy.normal_matrix, eager.normal_matrix)
    np.testing.assert_array_equal(lazy.gradient, eager.gradient)


def test_the_nominal_check_screen_reads_s0_from_one_jacobian_pass(twin500):
    """The screen stops on the pre-fits' tolerance without a Jacobian at its end: one
    Jacobian pass (two before) on these poses, its s0 that of the screen run to the
    calibration's tolerance within 1e-5 (the check compares it against 1.2)."""
    robot, meas = twin500
    opts = CalibrationOptions()
    res = calibrate(robot, meas, "full", opts)
    screen, n = _jacobians(
        lambda: _without_geometry_priors(res, robot, meas, opts, from_fit=True)
    )
    assert screen is not None and n == 1
    # The same screen run to the calibration's tolerance (stage 3 as the calibration
    # runs it), from the same workspace.
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(nc, "SCREEN_FIT", FullStage())
        tight, n_tight = _jacobians(
            lambda: _without_geometry_priors(res, robot, meas, opts, from_fit=True)
        )
    assert tight is not None and n_tight == 2
    assert abs(screen.sigma0 / tight.sigma0 - 1.0) < 1e-5
    assert screen.calibrated.status == tight.calibrated.status


def test_the_calibration_command_takes_few_jacobian_passes(twin500):
    """The calibration and its nominal check on 500 twin poses: 10 + 1 Jacobian passes
    (11 + 2 before; the whole command on 2000 twin poses 13 -> 11), and registration
    one of them (at its solution, where stage 1 starts)."""
    robot, meas = twin500
    res, n_fit = _jacobians(lambda: calibrate(robot, meas, "full"))
    found, n_check = _jacobians(lambda: nominal_check(res, robot, meas))
    assert n_fit <= 10 and n_check <= 1
    problem = Problem.make(robot, meas, "full")
    state, n_reg = _jacobians(lambda: Register()(problem, problem.start()))
    assert n_reg == 1
    np.testing.assert_allclose(state.x, res.registered, rtol=0.0, atol=1e-15)
    assert not [d for d in found if d.code in ("priors_held", "nominal_mismatch")]


@functools.cache
def _frame_cases():
    """(model, x, measurements, inputs, frames) of point, pose and sensor data, and of
    real data with two sets and three markers, at a registered point (compliance
    zero)."""
    from kinecal.simulation import experiment1
    from kinecal.workflows._simulate import simulate_paper_experiment

    e2 = simulate_paper_experiment(2, n_train=60).experiment
    e1 = experiment1(0, n_train=40)
    out = []
    for e, kind in ((e2, "point"), (e2, "pose"), (e1, "sensor")):
        meas = exact_pose_data(e.truth, e.train) if kind == "pose" else e.train
        assert meas.kind == kind
        out.append(_registered(e.truth.robot, meas))
    out += _real_cases()
    return out


def _registered(robot, meas):
    problem = Problem.make(robot, meas, "full")
    state = Register()(problem, problem.start())
    return state.model, state.x, meas, problem.inputs, problem.frames


def _real_cases():
    """The FR3 camera poses of two set-ups as two sets (user frames), and the TIAGo
    mocap points of three markers (cam frames)."""
    import tempfile
    from pathlib import Path

    from kinecal.io import read_measurements
    from kinecal.robot import load_robot

    real = Path(__file__).resolve().parents[1] / "data" / "real"
    fr3 = load_robot("franka-fr3")
    text_a = (real / "fr3_session_a.csv").read_text().splitlines()
    text_b = (real / "fr3_session_b_board_moved.csv").read_text().splitlines()
    both = ["set," + text_a[0]] + ["A," + r for r in text_a[1:]]
    both += ["B," + r for r in text_b[1:]]
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "both.csv"
        f.write_text("\n".join(both) + "\n")
        two_sets = read_measurements(f, fr3)
    tiago = load_robot(
        real.parents[2] / "examples/data/tiago_figaroh_qualisys/tiago.yaml"
    )
    markers = read_measurements(real / "tiago_mocap.csv", tiago)
    assert two_sets.set_labels == ("A", "B") and len(markers.marker_labels) == 3
    return [_registered(fr3, two_sets), _registered(tiago, markers)]


@pytest.mark.parametrize(
    "case", range(5), ids=["point", "pose", "sensor", "fr3-two-sets", "tiago-markers"]
)
def test_the_frame_fit_gives_the_models_residuals_and_normal_equations(case):
    """At frames away from the registered ones, the frame fit's residuals and the
    normal equations of the frames' columns (robust row weights or not) are the
    model's, to rounding; another column is refused."""
    from kinecal.measurement._residuals import Weights, residuals

    cm, x, meas, inputs, frames = _frame_cases()[case]
    fit = FrameFit.of(cm, x, meas, inputs)
    assert fit is not None
    y = x.copy()
    y[frames] += 1e-2 * np.random.default_rng(case).standard_normal(frames.sum())
    w = Weights.default(meas)
    mine = fit(cm, y, w, jacobian=True)
    model = residuals(cm, y, meas, w, inputs=inputs, jacobian=True)
    np.testing.assert_allclose(
        mine.r, model.r, rtol=0.0, atol=1e-9 * abs(model.r).max()
    )
    np.testing.assert_allclose(
        mine.raw_position, model.raw_position, rtol=0, atol=1e-13
    )
    cols = np.flatnonzero(frames)
    scales = cm.layout.scales[cols]
    assert mine.jacobian is not None
    for rw in (None, np.linspace(0.5, 1.0, meas.n)):
        A, g = mine.jacobian.normal(cols, scales, rw)
        A0, g0 = model.normal(cols, scales, rw)
        np.testing.assert_allclose(A, A0, rtol=0.0, atol=1e-12 * abs(A0).max())
        np.testing.assert_allclose(g, g0, rtol=0.0, atol=1e-9 * abs(g0).max())
    assert fit.rms_mm(cm, y, w) == pytest.approx(
        float(np.sqrt(np.mean(np.sum(model.raw_position**2, axis=1)))) * 1e3,
        rel=1e-12,
    )
    with pytest.raises(ValueError, match="another parameter"):
        mine.jacobian.normal(np.flatnonzero(~frames)[:1], np.ones(1))


def test_the_frame_fit_is_refused_where_a_deflection_moves_with_the_frames():
    """A compliance term not zero (the payload's torque moves with the tool): no frame
    fit, registration by the model as before."""
    cm, x, meas, inputs, _ = _frame_cases()[0]
    y = x.copy()
    y[next(i for i, s in enumerate(cm.layout.specs) if s.kind == "compliance")] = 1e-6
    assert FrameFit.of(cm, y, meas, inputs) is None
