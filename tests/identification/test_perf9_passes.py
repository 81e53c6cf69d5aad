"""Issue 36 (perf9): passes a calibration no longer makes, with the same numbers.

* The rejection's test fit (rows far from the robust probe left out) starts from the
  accepted fit's evaluation at its solution, its rows sliced: one Jacobian pass and one
  forward pass fewer, the same test fit and the same calibration.
* The evaluation cache keeps the raw errors of the points it pushes out: a result's
  "before" at the registered point costs no forward pass, and residuals formed from the
  raw errors under any weights are those of a new pass, to the last bit.
* The residual structure's ranks (one stable sort for every column) and a layout's
  scales (formed once) are those of before.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import kinecal.identification._robust as robust
from kinecal.identification import calibrate
from kinecal.identification._problem import EvaluationCache
from kinecal.identification._structure import _ranks
from kinecal.measurement import Weights, residuals
from kinecal.models import pass_counts


@pytest.fixture(scope="module")
def twin500():
    from kinecal.workflows._simulate import simulate_paper_experiment

    e = simulate_paper_experiment(2, n_train=500).experiment
    return e.truth.robot, e.train


@pytest.fixture(scope="module")
def suspect(twin500):
    """The twin's poses with one row 8 sigma off: beyond the chi quantile (a suspect of
    the robust probe) but not standing apart (no row is rejected)."""
    robot, meas = twin500
    p = meas.p.copy()
    p[7, 2] += 8 * meas.sigma[7]
    return robot, dataclasses.replace(meas, p=p)


def _with_test_fits(robot, meas, monkeypatch):
    """The calibration, and each test fit's (Jacobian passes, forward passes, x)."""
    fits = []
    orig = robust._test_fit

    def counted(root, current, rows):
        a = pass_counts()
        out = orig(root, current, rows)
        b = pass_counts()
        fits.append((b["jacobian"] - a["jacobian"], b["forward"] - a["forward"], out.x))
        return out

    monkeypatch.setattr(robust, "_test_fit", counted)
    return calibrate(robot, meas, "full"), fits


def test_the_test_fit_starts_from_the_accepted_fits_evaluation(suspect, monkeypatch):
    robot, meas = suspect
    res, fits = _with_test_fits(robot, meas, monkeypatch)
    assert res.success and not res.rejected and len(fits) == 1
    # Only the Jacobian at the lifted start: the evaluation at the solution is sliced.
    assert fits[0][:2] == (1, 0)
    # Without the slice: one more pass of each kind, the same test fit and result.
    monkeypatch.setattr(robust, "_start_held", lambda *args: None)
    res2, fits2 = _with_test_fits(robot, meas, monkeypatch)
    assert fits2[0][:2] == (2, 1)
    assert np.array_equal(fits[0][2], fits2[0][2])
    assert np.array_equal(res.params, res2.params)
    assert np.array_equal(res.covariance, res2.covariance)
    assert res.metrics_after == res2.metrics_after


def test_the_slice_is_a_new_pass_on_the_rows(suspect):
    """What the subset's cache serves equals a pass on the rows, in its layout."""
    from kinecal.identification._problem import Problem

    robot, meas = suspect
    res = calibrate(robot, meas, "full")
    problem = Problem.make(robot, meas, "full")
    cm, x = res.model, res.params
    w = Weights(meas.sigma)
    full = problem.evaluations(cm, x, w, jacobian=True, products=True)
    rows = np.ones(meas.n, bool)
    rows[[3, 7, 400]] = False
    state = problem.start().but(model=cm, x=x, weights=w)
    sub_w = w.subset(rows)
    sub = problem.on(state.but(active=rows, weights=sub_w))
    robust._start_held(problem, sub, state, rows, sub_w)
    served = sub.evaluations(cm, x, sub_w, jacobian=True, products=True)
    assert served.J is not None and full.J is not None
    fresh = residuals(
        cm,
        x,
        meas.subset(rows),
        sub_w,
        inputs=sub.inputs,
        jacobian=True,
        products=True,
    )
    assert np.array_equal(served.r, fresh.r)
    assert np.array_equal(served.J, fresh.J)
    assert served.J.strides == fresh.J.strides  # the products read the same layout
    assert np.array_equal(served.raw_position, fresh.raw_position)


def test_the_cache_keeps_raw_errors_of_points_it_pushed_out(twin500):
    robot, meas = twin500
    cm = calibrate(robot, meas, "kinematic").model
    ev = EvaluationCache(meas, meas.model_inputs(), keep=2)
    w = Weights(meas.sigma)
    x0 = cm.definition.nominal.copy()
    xs = [x0 + 1e-6 * k for k in range(4)]
    first = ev(cm, xs[0], w, jacobian=True)
    for x in xs[1:]:
        ev(cm, x, w)
    before = pass_counts()
    again = ev(cm, xs[0], w)  # pushed out: from its raw errors
    other = Weights(2.0 * meas.sigma)
    reweighted = ev(cm, xs[0], other)
    assert pass_counts() == before
    assert again.J is None and np.array_equal(again.r, first.r)
    fresh = residuals(cm, xs[0], meas, other, inputs=ev.inputs)
    assert np.array_equal(reweighted.r, fresh.r)
    assert np.array_equal(reweighted.raw_position, fresh.raw_position)
    # A Jacobian there is a new pass, as before.
    ev(cm, xs[0], w, jacobian=True)
    assert pass_counts()["jacobian"] == before["jacobian"] + 1


def test_a_results_before_costs_no_forward_pass(twin500, monkeypatch):
    """The registered point's errors (the result's "before") come from the raw errors
    kept since registration: without them a forward pass more, the same metrics."""
    import kinecal.identification._problem as problem_mod

    robot, meas = twin500
    a = pass_counts()["forward"]
    res = calibrate(robot, meas, "full")
    kept = pass_counts()["forward"] - a
    monkeypatch.setattr(problem_mod, "_RAW_POINTS", 0)
    a = pass_counts()["forward"]
    res2 = calibrate(robot, meas, "full")
    # ... and the rejection's probe, which starts there too (the next test)
    assert pass_counts()["forward"] - a == kept + 2
    assert res.metrics_before == res2.metrics_before
    assert np.array_equal(res.params, res2.params)


def test_ranks_of_every_column_at_once_are_those_of_each_alone():
    rng = np.random.default_rng(3)
    B = rng.integers(0, 7, size=(300, 5)).astype(float)  # many ties
    B[:, 4] = rng.standard_normal(300)

    def one(v):
        order = np.argsort(v, kind="stable")
        r = np.empty(v.size)
        r[order] = np.arange(v.size, dtype=float)
        return r

    got = _ranks(B)
    assert np.array_equal(got, np.column_stack([one(b) for b in B.T]))
    assert np.array_equal(_ranks(B[:, 0]), one(B[:, 0]))


def test_layout_scales_are_formed_once_and_read_as_copies(twin500):
    robot, meas = twin500
    layout = calibrate(robot, meas, "kinematic").model.layout
    s = layout.scales
    expected = np.array([sp.unit.scale for sp in layout.specs])
    assert np.array_equal(s, expected)
    s[:] = 0.0  # a caller's copy: the layout keeps its own
    assert np.array_equal(layout.scales, expected)
    names = layout.names
    names.append("x")
    assert layout.names == [sp.name for sp in layout.specs]


def test_row_z_reads_the_errors_the_cache_keeps(twin500):
    """The rejection's z of every row at a point the cache holds: no forward pass, the
    numbers of a pass under the default weights."""
    from kinecal.identification._problem import Problem
    from kinecal.identification._robust import row_z

    robot, meas = twin500
    problem = Problem.make(robot, meas, "full")
    state = problem.start()
    x = state.x + 1e-7 * problem.model.layout.scales
    state = state.but(x=x)
    problem.evaluations(state.model, x, state.weights, jacobian=True)
    before = pass_counts()
    _, err, r = row_z(problem, state)
    assert pass_counts() == before
    fresh = residuals(
        state.model, x, meas, Weights.default(meas), inputs=problem.inputs
    )
    assert np.array_equal(r, fresh.r)
    assert np.array_equal(err, np.linalg.norm(fresh.raw_position, axis=1) * 1e3)
    # At a point it does not hold: one pass, as before.
    before = pass_counts()
    row_z(problem, state.but(x=x + 1e-7 * problem.model.layout.scales))
    assert pass_counts()["forward"] == before["forward"] + 1


def test_the_probe_reads_the_registered_points_errors(twin500, monkeypatch):
    """The rejection's robust probe (a workspace of its own) starts at the registered
    point, whose raw errors the calibration's cache keeps: without them one forward
    pass more, the same calibration."""
    robot, meas = twin500
    a = pass_counts()["forward"]
    res = calibrate(robot, meas, "full")
    shared = pass_counts()["forward"] - a
    monkeypatch.setattr(robust, "share_raw", lambda src, dst: None)
    a = pass_counts()["forward"]
    res2 = calibrate(robot, meas, "full")
    assert pass_counts()["forward"] - a == shared + 1
    assert np.array_equal(res.params, res2.params)
    assert np.array_equal(res.covariance, res2.covariance)
