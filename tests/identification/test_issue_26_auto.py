"""``--model auto`` with its work shared (issue 26.3): the scores of an exact
cross-validation, a fraction of its cost."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.identification import (
    CalibrationOptions,
    candidate_specs,
    cross_validate,
    make_folds,
    select_model,
)
from kinecal.identification._lm import Prior
from kinecal.identification._solve import run_lm
from kinecal.identification.selection._candidates import fit_candidate, shared_fit
from kinecal.identification.selection._foldfit import FoldStep, every_row
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, experiment2

ROBOT = load_robot("fanuc-lrmate200id")


@pytest.fixture(scope="module")
def poses_300():
    e = experiment2(31, tracker=LaserTracker(5e-6, 0.0))
    return e.test.subset(np.random.default_rng(3).permutation(e.test.n)[:300])


@pytest.mark.parametrize("scheme", ["random", "region"])
def test_issue_26_auto_scores_are_those_of_calibrations_fold_by_fold(poses_300, scheme):
    """Every fold calibrated from nominal kinematics (registration, priors and their
    evidence, three stages: cross_validate) against the shared hyperparameters and the
    warm fold fits of select_model: the same held-out RMS within 3 %, on random folds
    and on whole regions of the workspace."""
    sel = select_model(ROBOT, poses_300, k=5, prior_scales=(1.0,), scheme=scheme)
    scored = {c.label: c for c in sel.candidates}
    for label in ("kinematic", "load", "full"):
        spec = scored[label].spec
        exact = cross_validate(ROBOT, poses_300, spec, k=5, scheme=scheme)
        got = scored[label].cv_rms_mm
        assert got == pytest.approx(exact.rms_mm, rel=0.03), (label, got, exact.rms_mm)


@pytest.mark.parametrize("label", ["kinematic", "full"])
def test_issue_26_a_folds_newton_step_lands_on_its_optimum(poses_300, label):
    """The fold fit from the downdated normal equations (with the link pairs' exact
    Hessian) reaches the training rows' optimum: no lower cost than a Levenberg-
    Marquardt run to the statistical stop from there, by more than the step's slack."""
    opts = CalibrationOptions()
    layouts = dict(candidate_specs(ROBOT, poses_300))
    shared = shared_fit(ROBOT, poses_300, layouts["full"], opts)
    fit = fit_candidate(
        ROBOT, poses_300, layouts[label], 1.0, opts, shared, [(shared.layout, shared.x)]
    )
    problem, cm = fit.problem()
    prior = Prior(fit.prior_mean, fit.prior_sigma)
    step = FoldStep.at(problem, cm, fit, prior, *every_row(problem, cm, fit))
    assert step is not None
    folds = make_folds(poses_300, 5, 0)
    accepted = 0
    for t in folds.test:
        held = np.zeros(poses_300.n, bool)
        held[t] = True
        train = shared.keep & ~held
        state = problem.start(train).but(
            model=cm, x=fit.x, weights=shared.weights(train)
        )
        view = problem.on(state)
        x, _, every = step.fold(lambda v=view, s=state: (v, s), held, fit.free)
        if x is None:
            continue  # the fold's LM takes over (tested through the scores)
        accepted += 1
        lm = replace(shared.lm, max_iter=200, stol=1e-8)
        _, res = run_lm(view, state, "check", x, fit.free, lm, prior, lifted=True)

        c_step, c_lm = (
            0.5 * float(np.sum(view.evaluations(cm, v, state.weights).r ** 2))
            + prior.cost(v)
            for v in (x, res.x)
        )
        assert c_step - c_lm <= 0.5, (label, c_step, c_lm)
        # The step moved the parameters: the fold's fit is not the candidate's.
        assert not np.allclose(x, fit.x)
        # Every row's residuals at the step's solution: the training rows' are those
        # of the training problem.
        np.testing.assert_allclose(
            every.r[train], view.evaluations(cm, x, state.weights).r, rtol=1e-12
        )
    assert accepted >= 3, accepted


def test_issue_26_an_overshooting_fold_step_is_damped(poses_300, monkeypatch):
    """A Newton step that overshoots (here made 30 times too long) raises the training
    cost: a damped step on the same normal equations takes its place and the Newton
    steps go on from there, to the optimum a Levenberg-Marquardt run reaches."""
    import kinecal.identification.selection._foldfit as foldfit

    opts = CalibrationOptions()
    layouts = dict(candidate_specs(ROBOT, poses_300))
    shared = shared_fit(ROBOT, poses_300, layouts["full"], opts)
    fit = fit_candidate(
        ROBOT,
        poses_300,
        layouts["full"],
        1.0,
        opts,
        shared,
        [(shared.layout, shared.x)],
    )
    problem, cm = fit.problem()
    prior = Prior(fit.prior_mean, fit.prior_sigma)
    step = FoldStep.at(problem, cm, fit, prior, *every_row(problem, cm, fit))
    held = np.zeros(poses_300.n, bool)
    held[make_folds(poses_300, 5, 0).test[0]] = True
    train = shared.keep & ~held
    state = problem.start(train).but(model=cm, x=fit.x, weights=shared.weights(train))
    view = problem.on(state)
    calls = []
    plain = foldfit.spd_solve

    def overshoot(A, b, rcond=None):
        calls.append(1)
        d = plain(A, b, rcond=rcond)
        return 30.0 * d if len(calls) == 1 else d  # the first (Newton) step only

    monkeypatch.setattr(foldfit, "spd_solve", overshoot)
    x, _, _ = step.fold(lambda: (view, state), held, fit.free)
    monkeypatch.undo()
    assert len(calls) > 2 and x is not None  # damped, then Newton again
    lm = replace(shared.lm, max_iter=200, stol=1e-8)
    _, res = run_lm(view, state, "check", fit.x, fit.free, lm, prior, lifted=True)
    c_step, c_lm = (
        0.5 * float(np.sum(view.evaluations(cm, v, state.weights).r ** 2))
        + prior.cost(v)
        for v in (x, res.x)
    )
    assert c_step - c_lm <= 0.5, (c_step, c_lm)


def test_issue_26_auto_runs_in_worker_processes_alike(poses_300, one_blas_thread):
    a = select_model(ROBOT, poses_300.subset(np.arange(120)), k=4, jobs=1)
    b = select_model(ROBOT, poses_300.subset(np.arange(120)), k=4, jobs=2)
    assert a.as_dict() == b.as_dict()


def test_issue_26_auto_on_too_few_poses_is_a_clear_identifiability_error(poses_300):
    from kinecal.errors import IdentifiabilityError

    with pytest.raises(IdentifiabilityError, match="measure more poses"):
        select_model(ROBOT, poses_300.subset(np.arange(11)), k=5)


def test_issue_26_the_chosen_largest_candidate_is_its_shared_calibration(poses_300):
    """When the largest candidate wins, the command's calibration of the choice is the
    selection's shared calibration, finished: the same numbers as calibrating it anew,
    under the chosen name; with other options, or another choice, there is none."""
    from dataclasses import replace as dc_replace

    from kinecal.identification import calibrate

    opts = CalibrationOptions()
    sel = select_model(ROBOT, poses_300, k=5, options=opts)
    assert sel.spec.name == "auto:full"  # the twin's link and transmission terms
    got = sel.calibration(opts)
    assert got is not None
    ref = calibrate(ROBOT, poses_300, sel.spec, opts)
    assert got.calibrated.info["model"] == ref.calibrated.info["model"] == "auto:full"
    np.testing.assert_array_equal(got.params, ref.params)
    np.testing.assert_array_equal(got.std, ref.std)
    assert got.calibrated.status == ref.calibrated.status
    assert [d.code for d in got.diagnostics] == [d.code for d in ref.diagnostics]
    assert sel.calibration(opts.tuned(prior_scale=2.0)) is None
    small = dc_replace(sel, spec=candidate_specs(ROBOT, poses_300)[0][1])
    assert small.calibration(opts) is None
