"""``--model auto``: choose the terms the data support by cross-validation.

Candidates run from the kinematic model to the full one (NTM per joint group and order,
payload compliance, link weight), each with the physical priors at a few strengths. Every
candidate is scored by k-fold cross-validation that imitates a new session: whole sessions
per fold when there are several (their user frames are refitted, as for a new set-up),
else whole regions of the workspace. The choice follows the one-standard-error rule:
the smallest model whose validation RMS is within 1.75 standard errors of the best (the
error taken on the paired per-fold log ratios of the RMS: the folds are the same for
every candidate), among those whose Fourier terms' coefficients are reproducible across
the folds and whose Fourier series is not cut below orders that are (:mod:`._rule`,
:mod:`._fourier`). The table behind the choice goes into the report. ``--cv`` scores
by the same path (:func:`cross_validate_models`): the same folds give the same figures.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal._parallel import parallel_map
from kinecal.errors import IdentifiabilityError
from kinecal.identification._calibrate import (
    CalibrationOptions,
    CalibrationResult,
    spec_for,
)
from kinecal.identification.selection import _crossval
from kinecal.identification.selection._candidates import (
    CandidateFit,
    Shared,
    fit_candidate,
    rescaled,
    shared_calibration,
    shared_fit,
)
from kinecal.identification.selection._crossval import (
    CrossValidation,
    Folds,
    make_folds,
)
from kinecal.identification.selection._foldfit import Score, run_folds
from kinecal.identification.selection._fourier import (
    FoldCoefficients,
    fold_fourier,
    fourier_notes,
)
from kinecal.identification.selection._rule import choose_candidate
from kinecal.measurement._measurements import Measurements
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import RobotDescription

__all__ = [
    "Candidate",
    "Selection",
    "candidate_specs",
    "choose_candidate",
    "cross_validate_models",
    "select_model",
]

Run = tuple[str, ModelSpec, float]  # label, layout, prior scale


@dataclass
class Candidate:
    """One candidate's cross-validation result."""

    label: str
    spec: ModelSpec
    prior_scale: float
    size: int
    cv_rms_mm: float
    cv_se_mm: float
    train_rms_mm: float
    chosen: bool = False
    fold_rms_mm: tuple[float, ...] = ()
    cv: CrossValidation | None = field(default=None, repr=False, compare=False)
    # its free Fourier coefficients in every fold's fit (:mod:`._fourier`)
    fold_fourier: FoldCoefficients = field(default_factory=dict, repr=False)


@dataclass
class Selection:
    """The chosen model and the table behind the choice."""

    spec: ModelSpec
    prior_scale: float
    candidates: list[Candidate] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    folds: int = 0
    shared: Shared | None = field(default=None, repr=False, compare=False)
    unit: str = "pose"  # what the folds held whole (see Folds)
    fold_sets: Folds | None = field(default=None, repr=False, compare=False)
    scorer: _Scorer | None = field(default=None, repr=False, compare=False)
    # a large set's sample the folds were made on (sample_rows: rows, groups, note)
    sample: tuple[Any, ...] | None = field(default=None, repr=False, compare=False)

    def chosen_cv(self, folds: Folds) -> CrossValidation | ValueError:
        """The chosen candidate's cross-validation on ``folds``: the table's own figures
        when the selection ran on the same folds, else its fit scored on them by the
        same path (an error of a fold that cannot determine it)."""
        chosen = next(c for c in self.candidates if c.chosen)
        if (
            chosen.cv is not None
            and self.fold_sets is not None
            and _same_folds(self.fold_sets, folds)
        ):
            return chosen.cv
        if self.scorer is None:
            raise ValueError("the selection's fits are not at hand (a copy of it)")
        run = (chosen.label, chosen.spec, chosen.prior_scale)
        (got,) = self.scorer.score([run], folds)
        return got.result

    def calibration(self, options: CalibrationOptions) -> CalibrationResult | None:
        """The calibration of the choice with ``options`` when the largest candidate at
        prior strength 1 won and the selection ran with the same options (its shared
        calibration, finished: the same numbers as
        :func:`~kinecal.identification.calibrate`); None otherwise."""
        if self.shared is None or self.prior_scale != 1.0:
            return None
        made = self.shared.made
        if made is None or made[0].options != options:
            return None
        return shared_calibration(self.shared, self.spec)

    def as_dict(self) -> dict[str, Any]:
        return {
            "chosen": self.spec.name,
            "prior_scale": self.prior_scale,
            "folds": self.folds,
            "fold_unit": self.unit,
            "rule": "smallest model within 1.75 standard errors (of the log ratios of the "
            "fold RMS, paired over folds), or "
            "1 %, of the best validation RMS; Fourier terms only when their "
            "coefficients are reproducible across the folds, and no series cut below "
            "reproducible orders",
            "candidates": [
                {
                    "label": c.label,
                    "parameters": c.size,
                    "prior_scale": c.prior_scale,
                    "cv_rms_mm": c.cv_rms_mm,
                    "cv_se_mm": c.cv_se_mm,
                    "train_rms_mm": c.train_rms_mm,
                    "chosen": c.chosen,
                }
                for c in self.candidates
            ],
            "warnings": self.warnings,
        }


def _same_folds(a: Folds, b: Folds) -> bool:
    return (
        a.unit == b.unit
        and len(a.test) == len(b.test)
        and all(np.array_equal(x, y) for x, y in zip(a.test, b.test, strict=True))
        and np.array_equal(a.always_train, b.always_train)
    )


def candidate_specs(
    robot: RobotDescription,
    meas: Measurements,
    *,
    hayati: tuple[int, ...] = (),
    ntm_joints: tuple[int, ...] | None = None,
) -> list[tuple[str, ModelSpec]]:
    """Candidate layouts from the kinematic model to the full one, smallest first
    (``ntm_joints``: the robot's default, :attr:`RobotDescription.ntm_joints`; the link
    terms: the robot's lumped layout or the general model of its link masses)."""
    base = spec_for(robot, meas, "kinematic", hayati=hayati)
    if ntm_joints is None:
        ntm_joints = robot.ntm_joints
    lumped = robot.self_weight is not None
    bodies = () if lumped else robot.link_bodies  # the general model's, from the masses
    has_link = lumped or bool(bodies)
    link = "paper" if lumped else ("general" if bodies else "none")
    out: list[tuple[str, ModelSpec]] = [("kinematic", base)]
    out.append(
        (
            f"ntm J{','.join(map(str, ntm_joints))} order 1",
            replace(base, ntm_joints=ntm_joints, ntm_order=1, name="ntm"),
        )
    )
    out.append(("ntm", replace(base, ntm_joints=ntm_joints, ntm_order=2, name="ntm")))
    out.append(("load", replace(base, load=True, name="load")))
    if lumped:
        out.append(("rfcm", replace(base, load=True, link="rfcm", name="rfcm")))
    if has_link:
        out.append(
            (
                "load+link",
                replace(
                    base, load=True, link=link, link_bodies=bodies, name="load+link"
                ),
            )
        )
    out.append(
        (
            "full order 1",
            replace(
                base,
                ntm_joints=ntm_joints,
                ntm_order=1,
                load=True,
                link=link,
                link_bodies=bodies,
                name="full",
            ),
        )
    )
    out.append(
        (
            "full",
            replace(
                base,
                ntm_joints=ntm_joints,
                ntm_order=2,
                load=True,
                link=link,
                link_bodies=bodies,
                name="full",
            ),
        )
    )
    return out


class _Scorer:
    """The one cross-validation path of ``--model auto`` and ``--cv``: candidates fitted
    on the kept rows from the shared fit, then scored fold by fold (the same folds give
    the same figures, whichever command asks)."""

    def __init__(
        self,
        robot: RobotDescription,
        meas: Measurements,
        opts: CalibrationOptions,
        shared: Shared,
        jobs: int = 1,
        say: Any = None,
    ) -> None:
        self.robot, self.meas, self.opts, self.shared = robot, meas, opts, shared
        self.jobs = jobs
        self.say = say or (lambda stage, detail: None)
        self.fitted: dict[tuple[str, float], CandidateFit] = {}

    def fit(self, label: str, spec: ModelSpec, scale: float) -> CandidateFit:
        """The candidate's fit on the kept rows (from the best point fitted before it).

        Raises
        ------
        IdentifiabilityError
            Too few rows for the candidate.
        """
        key = (label, scale)
        if key in self.fitted:
            return self.fitted[key]
        same = self.fitted.get((label, 1.0))
        starts = [(self.shared.layout, self.shared.x)] + [
            (f.layout, f.x) for f in self.fitted.values() if f.spec != spec
        ]
        if same is not None:
            starts.insert(0, (same.layout, same.x))
        if same is not None and same.spec == spec and scale != 1.0:
            fit = rescaled(same, scale)  # a variant of a fitted layout
        else:
            fit = fit_candidate(
                self.robot, self.meas, spec, scale, self.opts, self.shared, starts
            )
        self.fitted[key] = fit
        return fit

    def score(self, runs: list[Run], folds: Folds) -> list[_Scored]:
        """Fit the runs, then cross-validate them on ``folds`` (each run's folds in a
        worker process when ``jobs`` > 1): per run its fit and cross-validation, or the
        error that stopped it."""
        tasks: list[tuple[Run, CandidateFit | ValueError]] = []
        done_here: list[list[Score]] = []
        for label, spec, scale in runs:
            self.say("auto", f"{label} (priors x{scale:g})")
            try:
                fit = self.fit(label, spec, scale)
            except IdentifiabilityError as exc:  # too few poses for this candidate
                tasks.append(((label, spec, scale), exc))
                continue
            if self.jobs <= 1:  # while the fit's own evaluations are at hand
                done_here.append(_folds_of((fit, folds)))
            fit = replace(fit, made=None)  # (its Jacobians need not stay)
            self.fitted[(label, scale)] = fit
            tasks.append(((label, spec, scale), fit))
        fits = [f for _, f in tasks if isinstance(f, CandidateFit)]
        per_run = iter(
            done_here or parallel_map(_folds_of, [(f, folds) for f in fits], self.jobs)
        )
        out: list[_Scored] = []
        for run, got in tasks:
            if isinstance(got, ValueError):
                out.append(_Scored(run, error=got))
                continue
            scores = next(per_run)
            failed = next((s for s in scores if isinstance(s, ValueError)), None)
            if failed is not None:  # too few poses for this candidate in a fold
                self.say("auto", f"{run[0]} (priors x{run[2]:g}) skipped: {failed}")
                out.append(_Scored(run, error=failed))
                continue
            cv = CrossValidation(run[1].name, unit=folds.unit, notes=folds.notes)
            xs = []
            for tr, te, x in scores:  # type: ignore[misc]
                cv.train.append(tr)
                cv.folds.append(te)
                xs.append(x)
            out.append(_Scored(run, cv, fourier=fold_fourier(got.layout, got.free, xs)))
        return out


@dataclass(frozen=True)
class _Scored:
    """A run's cross-validation, or the error that stopped it."""

    run: Run
    cv: CrossValidation | None = None
    error: ValueError | None = None
    fourier: FoldCoefficients = field(default_factory=dict)

    @property
    def result(self) -> CrossValidation | ValueError:
        assert self.cv is not None or self.error is not None
        return self.cv if self.cv is not None else self.error  # type: ignore[return-value]


def _folds_of(task: tuple[CandidateFit, Folds]) -> list[Score]:
    fit, folds = task
    return run_folds(fit, folds.test, folds.always_train, folds.unit)


def _candidate(robot: RobotDescription, got: _Scored) -> Candidate:
    from kinecal.models import CalibrationModel

    (label, spec, scale), cv = got.run, got.cv
    assert cv is not None
    train = float(np.sqrt(np.mean([m.rms_mm**2 for m in cv.train])))
    return Candidate(
        label,
        spec,
        scale,
        CalibrationModel(robot, spec).size,
        cv.rms_mm,
        cv.rms_se_mm,
        train,
        fold_rms_mm=tuple(f.rms_mm for f in cv.folds),
        cv=cv,
        fold_fourier=got.fourier,
    )


def _shared_of(
    robot: RobotDescription,
    meas: Measurements,
    layouts: list[tuple[str, ModelSpec]],
    opts: CalibrationOptions,
    say: Any,
    n_folds: int,
) -> Shared:
    """The shared fit: the largest of ``layouts`` the data can determine."""
    for label, spec in reversed(layouts):
        say("auto", f"{label}: on every row (gross errors, weights, priors)")
        try:
            return shared_fit(robot, meas, spec, opts)
        except IdentifiabilityError as exc:
            say("auto", f"{label} skipped: {exc}")
    raise IdentifiabilityError(
        f"{meas.source}: no candidate model could be cross-validated: {meas.n} "
        f"poses in {n_folds} folds leave too few for even the kinematic model; "
        "measure more poses or give a fixed --model."
    )


@one_blas_thread()
def cross_validate_models(
    robot: RobotDescription,
    meas: Measurements,
    models: list[tuple[str, ModelSpec]],
    folds: list[Folds],
    *,
    options: CalibrationOptions | None = None,
    jobs: int = 1,
    progress: object | None = None,
) -> list[CrossValidation | ValueError]:
    """Cross-validate (label, layout) pairs on each of ``folds`` by the path of
    :func:`select_model` (what ``--cv`` reports): the hyperparameters (gross errors,
    weights, priors' widths) of a shared fit of the largest of ``models``, each model
    fitted on the kept rows and every fold fitted from there. Per folds and model (in
    that order) its cross-validation, or the error that stopped it."""
    opts = options or CalibrationOptions()
    say = progress if callable(progress) else (lambda stage, detail: None)
    ordered = sorted(models, key=lambda m: CalibrationModel(robot, m[1]).size)
    shared = _shared_of(robot, meas, ordered, opts, say, len(folds[0].test))
    scorer = _Scorer(robot, meas, opts, shared, jobs, say)
    out: list[CrossValidation | ValueError] = []
    for f in folds:
        for got in scorer.score([(label, spec, 1.0) for label, spec in models], f):
            out.append(got.result)
    return out


@one_blas_thread()
def select_model(
    robot: RobotDescription,
    meas: Measurements,
    *,
    options: CalibrationOptions | None = None,
    k: int = 5,
    seed: int = 0,
    prior_scales: tuple[float, ...] | None = None,
    hayati: tuple[int, ...] = (),
    ntm_joints: tuple[int, ...] | None = None,
    progress: object | None = None,
    jobs: int = 1,
    groups: np.ndarray | None = None,
    group_name: str = "group",
    scheme: str = "region",
) -> Selection:
    """Choose a model by k-fold cross-validation and the one-standard-error rule.

    The folds (:func:`~kinecal.identification.make_folds`) imitate what a calibration
    is used for: whole sessions when the data have several sets, else whole regions of
    the workspace (``scheme='region'``, the default; ``'random'``: poses drawn at
    random), or the user's ``groups``. Each layout is cross-validated with priors at
    strength 1; the best layout is then tried with its priors scaled by
    ``prior_scales`` (by default 0.3 and 3 only when the priors are not scaled by their
    evidence). The rule (:func:`._rule.choose_candidate`): among the candidates within
    1.75 paired standard errors of the best, the smallest wins. ``jobs`` > 1 runs the
    folds in that many worker processes (the same result).

    Work is shared (:mod:`._candidates`): one calibration of the largest candidate on
    every row decides the gross errors, the weights and the priors' widths for all;
    each candidate starts on the kept rows from the best point before it, and each of
    its folds is fitted from there (the folds' fits go to the worker processes).
    """
    opts = options or CalibrationOptions()
    say = progress if callable(progress) else (lambda stage, detail: None)
    sampled = None
    if meas.n > _crossval.CV_MAX_ROWS:  # the choice on a sample of a large set
        meas, groups, sampled = _crossval.sample_rows(meas, groups, seed)
    folds = make_folds(
        meas, k, seed, groups=groups, group_name=group_name, scheme=scheme, robot=robot
    )
    layouts = candidate_specs(robot, meas, hayati=hayati, ntm_joints=ntm_joints)
    shared = _shared_of(robot, meas, layouts, opts, say, len(folds.test))
    scorer = _Scorer(robot, meas, opts, shared, jobs, say)
    cands: list[Candidate] = []

    def run(runs: list[Run]) -> None:
        for got in scorer.score(runs, folds):
            if got.cv is not None:
                label, _, scale = got.run
                say(
                    "auto",
                    f"{label} (priors x{scale:g}): held-out RMS {got.cv.rms_mm:.4f} mm",
                )
                cands.append(_candidate(robot, got))

    run([(label, spec, 1.0) for label, spec in layouts])
    if not cands:
        raise IdentifiabilityError(
            f"{meas.source}: no candidate model could be cross-validated: {meas.n} "
            f"poses in {len(folds.test)} folds leave too few for even the kinematic "
            "model; measure more poses or give a fixed --model."
        )
    best = min(cands, key=lambda c: c.cv_rms_mm)
    if prior_scales is None:
        prior_scales = (1.0,) if opts.tuning.adapt_priors else (0.3, 1.0, 3.0)
    if opts.priors != "none":  # the best layout with other prior strengths
        run([(best.label, best.spec, s) for s in prior_scales if s != 1.0])
    chosen = choose_candidate(cands)
    spec = replace(chosen.spec, name=f"auto:{chosen.label}")
    notes = _warnings(cands) + fourier_notes(cands, chosen)
    if sampled is not None:
        notes.append(f"{sampled}; the chosen model is calibrated on every row")
    # (a sample's shared fit is not the calibration on every row: none to finish)
    kept = shared if sampled is None else None
    sel = Selection(spec, chosen.prior_scale, cands, notes, len(folds.test), kept)
    sel.unit, sel.fold_sets, sel.scorer = folds.unit, folds, scorer
    sel.sample = None if sampled is None else (meas, groups, sampled, seed)
    return sel


def _warnings(cands: list[Candidate]) -> list[str]:
    warnings = []
    ordered = sorted(
        {c.label: c for c in cands if c.prior_scale == 1.0}.values(),
        key=lambda c: c.size,
    )
    for a, b in itertools.pairwise(ordered):
        if b.train_rms_mm < a.train_rms_mm and b.cv_rms_mm > a.cv_rms_mm * 1.02:
            warnings.append(
                f"{b.label}: training error falls "
                f"({a.train_rms_mm:.4f} -> {b.train_rms_mm:.4f} mm) "
                f"while validation error rises ({a.cv_rms_mm:.4f} -> {b.cv_rms_mm:.4f} mm): "
                "the extra terms fit noise."
            )
    return warnings
