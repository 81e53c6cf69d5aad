"""Issue 36, point 3: fewer passes over the data, the same numbers.

The rejection's robust probe and the nominal check start from the calibration's own state
after registration and the identifiability analysis (neither depends on the loss or the
priors) instead of computing it again.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from kinecal.identification import CalibrationOptions, calibrate, default_stages
from kinecal.identification._nominal_check import _without_geometry_priors
from kinecal.identification._problem import Problem, run_stages
from kinecal.identification._robust import RobustRejection, _probe, row_z
from kinecal.models import pass_counts


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


def test_the_rejection_probe_from_the_shared_state_is_the_same(exp2_exact):
    """The robust kinematic probe started from the fit's identified state gives the
    same row z as the probe run from the nominal start."""
    e = exp2_exact
    problem = Problem.make(e.truth.robot, e.train, "full", CalibrationOptions())
    stages = default_stages()
    state = run_stages(problem, problem.start(), stages[:2])
    rejection = next(s for s in stages if isinstance(s, RobustRejection))
    rob = problem.with_options(dataclasses.replace(problem.options, loss="huber"))
    shared, n_shared = _jacobians(lambda: _probe(rob, state, rejection.probe))
    fresh, n_fresh = _jacobians(
        lambda: _probe(rob, state.but(identified=None), rejection.probe)
    )
    np.testing.assert_array_equal(shared.x, fresh.x)
    np.testing.assert_array_equal(row_z(rob, shared)[0], row_z(rob, fresh)[0])
    assert n_shared < n_fresh
