"""The fold calibrations of ``--model auto`` with the work the candidates share done once.

Every candidate of :func:`~kinecal.identification.select_model` is the kinematic model
plus some compliance terms, and its calibration starts alike: the registration, the
identifiability of the kinematic parameters, the priors' pre-fit and stage 1 see the
compliance terms at zero, where every candidate's model is the kinematic one. So each
fold runs those stages once (:data:`PREFIX`, on the kinematic candidate) and every
candidate goes on from there with its own stages (:data:`TAIL`: stage 2, stage 3, the
noise model, the evidence priors), started from the largest candidate fitted before it
whose terms it contains (a warm start: stage 3's optimum is unique, so only the path
changes, by less than the statistical stop resolves). The variants of the best layout
with other prior strengths start from its fit at strength 1 in the same fold.

Gross errors are decided once, on every row, by a calibration with the largest
candidate (:func:`rejected_rows`): a bumped reflector is an error of the data whatever
the model, and a held-out one scores nothing. The folds then leave those rows out, and
fit without rejection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from kinecal.identification._calibrate import (
    CalibrationOptions,
    CalibrationResult,
    calibrate,
    default_stages,
)
from kinecal.identification._evaluate import evaluate
from kinecal.identification._measurements import Measurements
from kinecal.identification._metrics import Metrics
from kinecal.identification._priors import (
    EvidencePriors,
    Priors,
    adapt_prior,
    build_prior,
)
from kinecal.identification._problem import Problem, State, run_stages
from kinecal.identification._robust import RobustRejection, chi2_isf, row_z
from kinecal.identification._stages import (
    FullStage,
    Identify,
    KinematicStage,
    Register,
    TransmissionStage,
)
from kinecal.models import ModelSpec
from kinecal.robot import RobotDescription

__all__ = ["AutoFold", "rejected_rows", "run_auto_fold"]

Run = tuple[str, ModelSpec, float]  # label, layout, prior scale
Score = tuple[Metrics, Metrics] | ValueError  # training and held-out metrics


def rejected_rows(
    robot: RobotDescription,
    meas: Measurements,
    spec: ModelSpec,
    options: CalibrationOptions,
) -> np.ndarray:
    """(N,) bool, the rows a calibration of ``spec`` on all of ``meas`` rejects as gross
    errors (none with ``options.reject == 'off'``).

    The robust kinematic fit that finds the suspects comes first (it is the same for
    every model); without suspects nothing is rejected and no calibration is needed.
    """
    out = np.zeros(meas.n, bool)
    if options.reject == "off":
        return out
    stages = default_stages(options)
    rr = stages[-3]
    assert isinstance(rr, RobustRejection)
    problem = Problem.make(robot, meas, spec, options)
    rob = problem.with_options(
        replace(options, loss=options.loss if options.loss != "linear" else "huber")
    )
    z, _, _ = row_z(rob, run_stages(rob, rob.start(), rr.probe))
    limit = options.reject_z
    if limit is None:
        limit = math.sqrt(chi2_isf(meas.components, options.outlier_p))
    if not np.any(z > limit):
        return out
    res = calibrate(robot, meas, spec, options)
    out[np.isin(meas.rows, [o.row for o in res.rejected])] = True
    return out


@dataclass(frozen=True)
class AutoFold:
    """One fold of ``--model auto`` (sent to a worker process).

    ``runs`` at prior scale 1 come first, smallest layout first, the kinematic one
    leading; ``variants`` are runs of one of them at other prior scales.
    """

    robot: RobotDescription
    meas: Measurements
    test_idx: np.ndarray
    keep: np.ndarray  # (N,) bool, rows not rejected as gross errors
    by_set: bool
    options: CalibrationOptions
    runs: tuple[Run, ...]
    variants: tuple[Run, ...] = ()


def run_auto_fold(f: AutoFold) -> list[Score]:
    """The training and held-out metrics of every run of the fold, in order."""
    from kinecal.identification._crossval import _relabel_sets

    mask = np.zeros(f.meas.n, bool)
    mask[f.test_idx] = True
    train, test = f.meas.subset(~mask & f.keep), f.meas.subset(mask)
    if f.by_set:
        train, test = _relabel_sets(train), _relabel_sets(test)
    opts = replace(f.options, reject="off")
    fitted: list[tuple[ModelSpec, State]] = []
    scores: list[Score] = []
    prefix: tuple[Problem, State, State] | None = None
    for _, spec, scale in f.runs:
        try:
            if prefix is None:
                prefix = _prefix(f.robot, train, spec, replace(opts, prior_scale=scale))
            problem, state = _tail(f.robot, train, spec, scale, opts, prefix, fitted)
        except ValueError as exc:  # too few poses for this candidate
            scores.append(exc)
            continue
        fitted.append((spec, state))
        scores.append(_score(problem, state, test, f.by_set))
    for label, spec, scale in f.variants:
        try:
            if prefix is None:
                raise ValueError(f"{label}: no kinematic fit to start from")
            base = _rescaled(f.robot, train, replace(opts, prior_scale=scale), prefix)
            same = [(s, st) for s, st in fitted if s == spec]
            problem, state = _tail(f.robot, train, spec, scale, opts, base, same)
        except ValueError as exc:
            scores.append(exc)
            continue
        scores.append(_score(problem, state, test, f.by_set))
    return scores


PREFIX = (Register(), Identify(), Priors())
TAIL = (TransmissionStage(), FullStage(), EvidencePriors())


def _prefix(
    robot: RobotDescription,
    train: Measurements,
    spec: ModelSpec,
    options: CalibrationOptions,
) -> tuple[Problem, State, State]:
    """The kinematic candidate's problem, its state after the priors (the pre-fit) and
    after stage 1."""
    problem = Problem.make(robot, train, spec, options)
    pre = run_stages(problem, problem.start(), PREFIX)
    return problem, pre, KinematicStage()(problem, pre)


def _rescaled(
    robot: RobotDescription,
    train: Measurements,
    options: CalibrationOptions,
    prefix: tuple[Problem, State, State],
) -> tuple[Problem, State, State]:
    """The prefix with the priors at another strength: the same pre-fit, the priors of
    the new scale adapted to it, stage 1 again."""
    problem0, pre, _ = prefix
    problem = problem0.with_options(options)
    assert pre.x_registered is not None
    prior = build_prior(pre.model, pre.x_registered, options)
    if options.adapt_priors and pre.prior is not None:
        prior, _ = adapt_prior(problem, pre, pre.x, pre.x_registered, prior)
    pre = pre.but(prior=prior)
    return problem, pre, KinematicStage()(problem, pre)


def _tail(
    robot: RobotDescription,
    train: Measurements,
    spec: ModelSpec,
    scale: float,
    options: CalibrationOptions,
    prefix: tuple[Problem, State, State],
    fitted: list[tuple[ModelSpec, State]],
) -> tuple[Problem, State]:
    """A candidate's calibration from the shared prefix, warm-started from the largest
    fitted candidate whose terms it holds."""
    problem_k, _, kin = prefix
    opts = replace(options, prior_scale=scale)
    if spec == problem_k.model.spec:
        return problem_k, kin
    problem = Problem.make(robot, train, spec, opts)
    cm = problem.model.with_references(
        kin.model.R_ref_base, kin.model.R_ref_cam if spec.cam_rotation else None
    )
    lay, lay_k = cm.layout, kin.model.layout
    x = lay.transfer(kin.x, lay_k)
    warm = [st for s, st in fitted if set(st.model.layout.names) <= set(lay.names)]
    if warm:  # the largest candidate inside this one, all its values
        src = max(warm, key=lambda st: st.model.size)
        x = lay.transfer(src.x, src.model.layout)
    assert kin.x_registered is not None and kin.prior is not None
    x_reg = lay.transfer(kin.x_registered, lay_k)
    prior = build_prior(cm, x_reg, opts)
    kin_names = [lay_k.names[i] for i in np.flatnonzero(problem_k.kinematic)]
    idx = [lay.index(n) for n in kin_names]
    prior.sigma[idx] = kin.prior.sigma[[lay_k.index(n) for n in kin_names]]
    state = problem.start().but(model=cm, x=x_reg)
    state = Identify()(problem, state)  # this layout's decisions (kinematic ones alike)
    state = state.but(
        x=x,
        x_registered=x_reg,
        prior=prior,
        weights=kin.weights,
        noise_estimated=kin.noise_estimated,
        noise_groups=kin.noise_groups,
        lm=kin.lm,
        stages=kin.stages,
    )
    return problem, run_stages(problem, state, TAIL)


def _score(problem: Problem, state: State, test: Measurements, by_set: bool) -> Score:
    res = CalibrationResult.from_state(problem, state)
    held = evaluate(res.calibrated, test, refit_user=by_set).metrics
    return res.metrics_after, held
