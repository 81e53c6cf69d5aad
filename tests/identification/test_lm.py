"""The Levenberg-Marquardt solver's statistical stop."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import LMOptions, solve_lm


def _noisy_rosenbrock(rng, m=400):
    """Rosenbrock's curved valley as two residuals among m - 2 of unit noise (whitened
    data: the a-posteriori variance of unit weight is about 1)."""
    noise = rng.normal(size=m - 2)

    def fun(x, jac):
        r = np.concatenate([[10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]], noise])[:, None]
        if not jac:
            return r, None
        J = np.zeros((m, 1, 2))
        J[0, 0] = [-20.0 * x[0], 10.0]
        J[1, 0] = [-1.0, 0.0]
        return r, J

    return fun


def test_statistical_stop_lands_within_a_small_fraction_of_a_sigma(rng):
    fun = _noisy_rosenbrock(rng)
    x0, free, scales = np.array([-1.2, 1.0]), np.ones(2, bool), np.ones(2)
    exact = solve_lm(fun, x0, free, scales, LMOptions(max_iter=500))
    stat = solve_lm(fun, x0, free, scales, LMOptions(max_iter=500, stol=1e-4))
    assert exact.success and stat.success
    assert stat.status == "stol" and stat.n_iter < exact.n_iter
    # The rule as documented: the last accepted step lowered the cost by at most
    # stol times the variance of unit weight, or the Gauss-Newton step from the solution
    # would lower it by at most that (then no step is taken).
    last = stat.log[-1]
    s0sq = 2.0 * stat.cost / (stat.residual.size - 2)
    A, g = stat.normal_matrix, stat.gradient
    gn = 0.5 * g @ np.linalg.solve(A, g)
    assert min(last["cost"] - last["cost_new"], gn) <= 1e-4 * s0sq
    # ... and the estimate is within a few percent of its standard deviation.
    cov = s0sq * np.linalg.inv(exact.normal_matrix)
    z = (stat.x - exact.x) / np.sqrt(np.diag(cov))
    assert np.abs(z).max() < 0.05, z


def test_issue_26_the_iterations_do_not_grow_with_the_data(rng):
    """A straight line fitted to 100 and to 100,000 noisy samples far from its origin
    (intercept and slope strongly correlated), from the same start: both runs end after
    as many iterations, though the second's standard deviations are 30x smaller. (With
    the damped steps alone and the stop on the last step's decrease they took 6 and 7.)"""

    def problem(n):
        t = np.linspace(10.0, 11.0, n)
        y = 0.5 + 0.2 * t + 0.05 * rng.normal(size=n)

        def fun(x, jac):
            r = (x[0] + x[1] * t - y)[:, None] / 0.05
            if not jac:
                return r, None
            return r, np.stack([np.ones_like(t), t], axis=1)[:, None, :] / 0.05

        return fun

    its = []
    for n in (100, 100_000):
        res = solve_lm(
            problem(n), np.zeros(2), np.ones(2, bool), np.ones(2), LMOptions(stol=1e-4)
        )
        assert res.success and res.status in ("stol", "gtol")  # gtol: at the optimum
        its.append(res.n_iter)
    assert its[0] == its[1] <= 4, its


@pytest.mark.parametrize("loose_stol, where", [(1e-1, "accept"), (1e-3, "top")])
def test_a_run_resumed_from_a_looser_stop_takes_the_same_iterates(loose_stol, where):
    """Issue 36: a run stopped on a loose ``stol`` (after a step, or on the Gauss-Newton
    test before one) and continued with a tighter one (``resume=``) ends where a run
    with the tighter one from the start ends, to the last bit, with its iteration count
    and log, and without its evaluations again."""
    fun = _noisy_rosenbrock(np.random.default_rng(0))
    calls = []

    def counted(x, jac):
        calls.append(jac)
        return fun(x, jac)

    x0, free, scales = np.array([-1.2, 1.0]), np.ones(2, bool), np.ones(2)
    loose = solve_lm(fun, x0, free, scales, LMOptions(max_iter=500, stol=loose_stol))
    assert loose.status == "stol" and loose.checkpoint is not None
    assert loose.checkpoint.where == where
    for stol in (1e-4, 1e-6):
        tight = LMOptions(max_iter=500, stol=stol)
        calls[:] = []
        fresh = solve_lm(counted, x0, free, scales, tight)
        n_fresh, calls[:] = len(calls), []
        on = solve_lm(counted, x0, free, scales, tight, resume=loose.checkpoint)
        np.testing.assert_array_equal(on.x, fresh.x)
        assert (on.cost, on.n_iter, on.status, on.log) == (
            fresh.cost,
            fresh.n_iter,
            fresh.status,
            fresh.log,
        )
        np.testing.assert_array_equal(on.normal_matrix, fresh.normal_matrix)
        assert len(calls) < n_fresh
    # A looser tolerance than the checkpoint's: a run from the start.
    looser = LMOptions(max_iter=500, stol=1.0)
    again = solve_lm(fun, x0, free, scales, looser, resume=loose.checkpoint)
    alone = solve_lm(fun, x0, free, scales, looser)
    np.testing.assert_array_equal(again.x, alone.x)
