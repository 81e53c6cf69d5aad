"""The cross-validation of ``--model auto`` with the work the candidates share done once.

Every candidate of :func:`~kinecal.identification.select_model` is the kinematic model
plus some compliance terms. What does not depend on the candidate is decided once, by a
calibration of the largest candidate on every row (:func:`shared_fit`): the rows
rejected as gross errors (a bumped reflector is an error of the data whatever the model,
and a held-out one scores nothing), the reference rotations of the frames, the noise
model (the weights) and the priors with their widths after the evidence scaling. These
are the hyperparameters of the comparison: a handful of numbers from every row, as a
rejection decided on all rows is.

Each candidate then starts on the kept rows with those weights from the best of the
points before it (:func:`fit_candidate`: the largest candidate's solution or another
candidate's point, transferred by parameter name; the lowest objective wins; the lifted
start where it has link terms), with its own identifiability and its own evidence
scaling of the priors; it is not fitted on every row itself. Other prior strengths (only
without the evidence scaling) refit the best layout from its point (:func:`rescaled`).
Each fold's training rows are fitted from the candidate's point (:mod:`._foldfit`): a
Newton step with the normal equations of every kept row less the held-out rows' (Eq.
(T-10)), kept when the training cost falls as its quadratic model says, otherwise up to
two more (a step that raises the cost damped first) and then the lifted
Levenberg-Marquardt run to the statistical stop. Every fold fit is a non-linear fit of
the candidate's free parameters on its training rows; only the hyperparameters are
shared. A user frame (or cam frame) whose set (marker) has no training row in a fold is
held: the fold's held-out sets are registered anew, as for a new set-up
(:func:`~kinecal.identification.evaluate` with ``refit_user``). On the tracker twin the
held-out RMS of every candidate is that of calibrating each fold from nominal to within
1 % (300 and 1000 poses) or 3 % (60 poses).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from kinecal.identification._calibrate import (
    CalibrationOptions,
    CalibrationResult,
    default_stages,
)
from kinecal.identification._diagnose import Diagnose
from kinecal.identification._lm import LMOptions, Prior, objective
from kinecal.identification._priors import EvidencePriors, build_prior, evidence_group
from kinecal.identification._problem import Problem, State, run_stages
from kinecal.identification._solve import (
    active_prior,
    lift_kept,
    run_lm,
    warm_options,
)
from kinecal.identification._stages import Identify
from kinecal.identification._uncertainty import Uncertainty
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import Weights
from kinecal.models import CalibrationModel, ModelSpec, ParameterLayout
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = [
    "CandidateFit",
    "Shared",
    "fit_candidate",
    "rescaled",
    "shared_calibration",
    "shared_fit",
]


@dataclass(frozen=True)
class Shared:
    """What every candidate shares, from the largest candidate's calibration.

    Attributes
    ----------
    keep : (N,) bool, the rows not rejected as gross errors.
    sigma, sigma_rot : (N,) the weights' sigmas per row (NaN on rejected rows).
    lm : the solver options of the data term (loss, where it bends, the stop).
    layout, x, x_registered, prior_mean, prior_sigma, free : the largest candidate's
        layout, its solution, its registered start, its priors and free parameters.
    R_ref_base, R_ref_cam : the frames' reference rotations.
    prior_factors : the evidence's scale of each group's priors in ``prior_sigma``.
    spec : the largest candidate.
    """

    keep: np.ndarray
    sigma: Float
    sigma_rot: Float | None
    lm: LMOptions
    layout: ParameterLayout
    x: Float
    x_registered: Float
    prior_mean: Float
    prior_sigma: Float
    free: np.ndarray
    R_ref_base: Float
    R_ref_cam: Float
    prior_factors: dict[str, float]
    spec: ModelSpec | None = None  # the largest candidate's layout
    # Its calibration's problem and final state, kept in this process (not sent to a
    # worker): when the largest candidate is chosen, the calibration of the choice.
    made: tuple[Problem, State, float] | None = field(
        default=None, compare=False, repr=False
    )

    def __getstate__(self) -> dict[str, object]:
        return {**self.__dict__, "made": None}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)

    def weights(self, rows: np.ndarray) -> Weights:
        """The weights of the rows ``rows`` (a mask over every row)."""
        return Weights(
            self.sigma[rows], None if self.sigma_rot is None else self.sigma_rot[rows]
        )


def shared_fit(
    robot: RobotDescription,
    meas: Measurements,
    spec: ModelSpec,
    options: CalibrationOptions,
) -> Shared:
    """Calibrate ``spec`` on every row (rejection included, no uncertainty) and keep
    what the candidates share."""
    t0 = time.perf_counter()
    problem = Problem.make(robot, meas, spec, options)
    stages = [
        s for s in default_stages(options) if not isinstance(s, (Uncertainty, Diagnose))
    ]
    state = run_stages(problem, problem.start(), stages)
    keep = np.ones(meas.n, bool) if state.active is None else state.active.copy()
    assert state.weights.sigma.shape == (int(keep.sum()),)
    sigma = np.full(meas.n, np.nan)
    sigma[keep] = state.weights.sigma
    sigma_rot = None
    if state.weights.sigma_rot is not None:
        sigma_rot = np.full(meas.n, np.nan)
        sigma_rot[keep] = state.weights.sigma_rot
    cm = state.model
    prior = state.prior or Prior.none(cm.size)
    assert state.x_registered is not None
    return Shared(
        keep,
        sigma,
        sigma_rot,
        state.lm,
        cm.layout,
        state.x,
        state.x_registered,
        prior.mean,
        prior.sigma,
        state.free,
        cm.R_ref_base,
        cm.R_ref_cam,
        dict(state.prior_factors),
        spec,
        (problem, state, time.perf_counter() - t0),
    )


def shared_calibration(shared: Shared, spec: ModelSpec) -> CalibrationResult | None:
    """The calibration of ``spec`` (the largest candidate, under another name) from the
    shared fit: its last stages (uncertainty, diagnosis) on the shared state, what
    :func:`~kinecal.identification.calibrate` of ``spec`` with the same options would
    compute from the start. None when the shared fit is not at hand (a worker
    process) or ``spec`` is another layout."""
    if shared.made is None or shared.spec is None:
        return None
    if replace(spec, name=shared.spec.name) != shared.spec:
        return None
    problem, state, seconds = shared.made
    t0 = time.perf_counter()
    state = state.but(model=state.model.with_spec(spec))  # the chosen name
    state = run_stages(problem, state, (Uncertainty(), Diagnose()))
    return CalibrationResult.from_state(
        problem, state, seconds + time.perf_counter() - t0
    )


@dataclass(frozen=True)
class CandidateFit:
    """A candidate's point on the kept rows (:func:`fit_candidate`; fitted only for the
    largest candidate and the prior-strength variants), and what its folds need (sent
    to a worker process: everything in it can be pickled)."""

    robot: RobotDescription
    meas: Measurements
    spec: ModelSpec
    options: CalibrationOptions
    shared: Shared
    x: Float
    free: np.ndarray
    prior_mean: Float
    prior_sigma: Float
    layout: ParameterLayout  # the candidate's
    # The fit's own problem, model and weights, kept in this process (not sent to a
    # worker): its evaluations hold the Jacobian at ``x`` the folds start from.
    made: tuple[Problem, CalibrationModel, Weights] | None = field(
        default=None, compare=False, repr=False
    )

    def problem(self) -> tuple[Problem, CalibrationModel]:
        """The candidate's problem and model (:func:`_problem`)."""
        if self.made is not None:
            return self.made[0], self.made[1]
        return _problem(self.robot, self.meas, self.spec, self.options, self.shared)

    def weights(self) -> Weights:
        """The weights of the kept rows, those the fit was made with."""
        if self.made is not None:
            return self.made[2]
        return self.shared.weights(self.shared.keep)

    def __getstate__(self) -> dict[str, object]:
        return {**self.__dict__, "made": None}

    def __setstate__(self, state: dict[str, object]) -> None:
        self.__dict__.update(state)


def _problem(
    robot: RobotDescription,
    meas: Measurements,
    spec: ModelSpec,
    options: CalibrationOptions,
    shared: Shared,
) -> tuple[Problem, CalibrationModel]:
    """A candidate's problem on every row, and its model with the shared reference
    rotations."""
    problem = Problem.make(robot, meas, spec, options)
    R_cam = shared.R_ref_cam if spec.cam_rotation else None
    return problem, problem.model.with_references(shared.R_ref_base, R_cam)


def fit_candidate(
    robot: RobotDescription,
    meas: Measurements,
    spec: ModelSpec,
    scale: float,
    options: CalibrationOptions,
    shared: Shared,
    starts: list[tuple[ParameterLayout, Float]],
) -> CandidateFit:
    """One candidate's point on the kept rows with the shared weights, where its folds
    start: the lowest-objective of ``starts`` (layouts and values, transferred by name;
    the registered start only without any), lifted where the candidate has link terms;
    its own identifiability, the shared priors before their evidence scaling and its
    own evidence scaling there. ``scale`` != 1 widens the priors that many times and
    fits (:func:`rescaled`). The largest candidate's point is its calibration.

    Raises
    ------
    IdentifiabilityError
        The data have no more residuals than the candidate has parameters.
    """
    if spec == shared.spec:  # the largest candidate: its calibration is the fit
        fit = CandidateFit(
            robot,
            meas,
            spec,
            options,
            shared,
            shared.x,
            shared.free,
            shared.prior_mean,
            shared.prior_sigma,
            shared.layout,
        )
        return fit if scale == 1.0 else rescaled(fit, scale)
    problem, cm = _problem(robot, meas, spec, options, shared)
    lay = cm.layout
    x_reg = lay.transfer(shared.x_registered, shared.layout)
    # Priors: those of the largest candidate (adapted to the data) before their
    # evidence scaling, the candidate's own physical ones for terms it lacks (another
    # link model); the candidate's own evidence scales them after its fit.
    base = build_prior(cm, x_reg, options.tuned(prior_scale=1.0))
    mean, sigma = base.mean.copy(), base.sigma.copy()
    for i, sp in enumerate(lay.specs):
        if sp.name in shared.layout:
            j = shared.layout.index(sp.name)
            mean[i] = shared.prior_mean[j]
            factor = shared.prior_factors.get(evidence_group(sp), 1.0)
            sigma[i] = shared.prior_sigma[j] / factor
    prior = Prior(mean, sigma)
    state = problem.start(shared.keep)
    state = state.but(model=cm, x=x_reg, weights=shared.weights(shared.keep))
    view = problem.on(state)
    # Its own identifiability: a term held in the largest candidate (redundant with a
    # term this one lacks) may be free here.
    state = Identify()(view, state)
    free = state.free
    w = state.weights
    lm = warm_options(shared.lm)
    # The lowest-objective start (each distinct one once; the registered start only
    # without a fit: a fitted one is far closer).
    unique = {x.tobytes(): x for x in (lay.transfer(v, source) for source, v in starts)}
    candidates = list(unique.values()) or [x_reg]
    costs = [
        objective(view.evaluations(cm, x, w).r, lm)[0] + _prior_cost(prior, x, free)
        for x in candidates
    ]
    x0 = candidates[int(np.argmin(costs))]
    # The candidate is not fitted here: its folds' Newton steps fit it (Eq. (T-10)), from
    # this start. Where it has link terms the start is the lifted one: the link moments
    # enter as products with the compliances, and from a start without them the folds
    # would crawl along that valley.
    state = state.but(prior=prior, lm=lm)
    if any(free[a] and free[b] for a, b in cm.link_products):
        x0 = lift_kept(view, cm, x0, free, lm, w, active_prior(prior, free))
    state = EvidencePriors(refit=False)(view, state.but(x=x0))
    prior = state.prior or prior
    fit = CandidateFit(
        robot,
        meas,
        spec,
        options,
        shared,
        state.x,
        free,
        prior.mean,
        prior.sigma,
        lay,
        (problem, cm, state.weights),
    )
    return fit if scale == 1.0 else rescaled(fit, scale)


def rescaled(fit: CandidateFit, scale: float) -> CandidateFit:
    """A fitted candidate with its priors (after the evidence) ``scale`` times wider,
    fitted again from its solution."""
    problem, cm = fit.problem()
    keep = fit.shared.keep
    sigma = np.where(problem.frames, fit.prior_sigma, fit.prior_sigma * scale)
    prior = Prior(fit.prior_mean, sigma)
    lm = warm_options(fit.shared.lm)
    state = problem.start(keep).but(
        model=cm, x=fit.x, weights=fit.shared.weights(keep), lm=lm, free=fit.free
    )
    view = problem.on(state)
    _, res = run_lm(
        view,
        state,
        f"auto: {fit.spec.name} priors x{scale:g}",
        fit.x,
        fit.free,
        lm,
        active_prior(prior, fit.free),
        lifted=True,
    )
    return replace(fit, x=res.x, prior_sigma=sigma)


def _prior_cost(prior: Prior, x: Float, free: np.ndarray) -> float:
    return prior.cost(x) if active_prior(prior, free) is not None else 0.0
