"""Issue 36, point 3: at most ~10 Jacobian passes for the whole calibration command.

The nominal check's screen (the fit without geometry priors from the calibration's
solution) reads only its ``s0``: it stops on the pre-fits' statistical tolerance and
takes no Jacobian at its solution.
"""

from __future__ import annotations

import numpy as np
import pytest

import kinecal.identification._nominal_check as nc
from kinecal.identification import CalibrationOptions, calibrate, nominal_check
from kinecal.identification._lm import LMOptions, solve_lm
from kinecal.identification._nominal_check import _without_geometry_priors
from kinecal.identification._stages import FullStage
from kinecal.models import pass_counts


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
    """The calibration and its nominal check on 500 twin poses: 11 + 1 Jacobian passes
    (11 + 2 before; the whole command on 2000 twin poses 13 -> 12)."""
    robot, meas = twin500
    res, n_fit = _jacobians(lambda: calibrate(robot, meas, "full"))
    found, n_check = _jacobians(lambda: nominal_check(res, robot, meas))
    assert n_fit <= 11 and n_check <= 1
    assert not [d for d in found if d.code in ("priors_held", "nominal_mismatch")]
