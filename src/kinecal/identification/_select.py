"""``--model auto``: choose the terms the data support by cross-validation.

Candidates run from the kinematic model to the full one (NTM per joint group and order,
payload compliance, link weight), each with the physical priors at a few strengths. Every
candidate is scored by k-fold cross-validation (whole sessions per fold when there are
several; their user frames are refitted, as for a new set-up). The choice follows the
one-standard-error rule: the smallest model whose validation RMS is within one standard
error of the best, the error taken on the paired per-fold differences (the folds are the
same for every candidate). The table behind the choice goes into the report.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from kinecal._parallel import parallel_map
from kinecal.errors import IdentifiabilityError
from kinecal.identification._autofit import (
    CandidateFit,
    Run,
    Score,
    Shared,
    fit_candidate,
    rescaled,
    shared_calibration,
    shared_fit,
)
from kinecal.identification._autofolds import run_folds
from kinecal.identification._calibrate import (
    CalibrationOptions,
    CalibrationResult,
    spec_for,
)
from kinecal.identification._crossval import CrossValidation, make_folds
from kinecal.identification._measurements import Measurements
from kinecal.models import ModelSpec
from kinecal.robot import RobotDescription

__all__ = ["Candidate", "Selection", "candidate_specs", "select_model"]


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


@dataclass
class Selection:
    """The chosen model and the table behind the choice."""

    spec: ModelSpec
    prior_scale: float
    candidates: list[Candidate] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    folds: int = 0
    shared: Shared | None = field(default=None, repr=False, compare=False)

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
            "rule": "smallest model within one standard error (paired over folds), or "
            "1 %, of the best validation RMS",
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


def _folds_of(
    task: tuple[CandidateFit, list[np.ndarray], np.ndarray, bool],
) -> list[Score]:
    return run_folds(*task)


def _within_one_se(c: Candidate, best: Candidate) -> bool:
    """One-standard-error rule on the paired fold differences.

    All candidates share the folds, so the fold-to-fold spread (which pose happened to be
    in which fold) is common to them; the standard error of the per-fold *differences*
    to the best candidate is the one that says whether ``c`` is really worse. A gain
    below :data:`_PRACTICAL` of the RMS does not count either: when every candidate
    predicts alike (the data hold no compliance), the paired error can be smaller than
    what separates them by chance, and extra terms must earn their place.
    """
    margin = _PRACTICAL * best.cv_rms_mm
    a, b = np.asarray(c.fold_rms_mm), np.asarray(best.fold_rms_mm)
    if a.size != b.size or a.size < 2:
        se = best.cv_se_mm if np.isfinite(best.cv_se_mm) else 0.0
        return c.cv_rms_mm <= best.cv_rms_mm + max(se, margin)
    d = a - b
    se_d = float(d.std(ddof=1) / np.sqrt(d.size))
    return c.cv_rms_mm - best.cv_rms_mm <= max(se_d, margin)


# A larger model must predict at least this much better (relative RMS) to be chosen.
_PRACTICAL = 0.01


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
) -> Selection:
    """Choose a model by k-fold cross-validation and the one-standard-error rule.

    Each layout is cross-validated with priors at strength 1; the best layout is then
    tried with its priors scaled by ``prior_scales`` (sigma times the scale). By default
    (None) that is 0.3 and 3 only when the priors are not scaled by their evidence
    (``options.adapt_priors`` off): the evidence already sets each group's strength, in
    finer steps and per group, and the two variants cost a fifth of the selection while
    they cross-validate alike (2000 twin poses: held-out RMS equal to 1e-5 mm). ``jobs`` > 1
    runs the folds in that many worker processes (the same result). The folds are those
    of :func:`~kinecal.identification.make_folds` (sets, poses or ``groups``).

    Work is shared (:mod:`._autofit`): one calibration of the largest candidate on
    every row decides the gross errors, the weights and the priors' widths for all;
    each candidate starts on the kept rows from the best point before it, and each of
    its folds is fitted from there (the folds' fits go to the worker processes).
    """
    opts = options or CalibrationOptions()
    say = progress if callable(progress) else (lambda stage, detail: None)
    cands: list[Candidate] = []
    folds = make_folds(meas, k, seed, groups=groups, group_name=group_name)
    n_folds = len(folds.test)
    from kinecal.models import CalibrationModel

    layouts = candidate_specs(robot, meas, hayati=hayati, ntm_joints=ntm_joints)
    shared = None
    for label, spec in reversed(layouts):  # the largest one the data can determine
        say("auto", f"{label}: on every row (gross errors, weights, priors)")
        try:
            shared = shared_fit(robot, meas, spec, opts)
            break
        except IdentifiabilityError as exc:
            say("auto", f"{label} skipped: {exc}")
    if shared is None:
        raise IdentifiabilityError(
            f"{meas.source}: no candidate model could be cross-validated: {meas.n} "
            f"poses in {n_folds} folds leave too few for even the kinematic model; "
            "measure more poses or give a fixed --model."
        )
    fitted: dict[tuple[str, float], CandidateFit] = {}

    def run(runs: list[Run]) -> None:
        """Fit the runs on the kept rows, then cross-validate them (the folds of each
        run in a worker process when ``jobs`` > 1)."""
        tasks: list[tuple[Run, CandidateFit | ValueError]] = []
        # Serially, each run's folds right after its fit.
        done_here: list[list[Score]] = []
        for label, spec, scale in runs:
            say("auto", f"{label} (priors x{scale:g})")
            same = fitted.get((label, 1.0))
            starts = [(shared.layout, shared.x)] + [
                (f.layout, f.x) for f in fitted.values() if f.spec != spec
            ]
            if same is not None:
                starts.insert(0, (same.layout, same.x))
            try:
                if same is not None and same.spec == spec and scale != 1.0:
                    fit = rescaled(same, scale)  # a variant of a fitted layout
                else:
                    fit = fit_candidate(robot, meas, spec, scale, opts, shared, starts)
                if jobs <= 1:  # while the fit's own evaluations are at hand
                    done_here.append(
                        _folds_of((fit, folds.test, folds.always_train, folds.by_set))
                    )
                fit = replace(fit, made=None)  # (its Jacobians need not stay)
                fitted.setdefault((label, scale), fit)
                tasks.append(((label, spec, scale), fit))
            except IdentifiabilityError as exc:  # too few poses for this candidate
                tasks.append(((label, spec, scale), exc))
        fits = [f for _, f in tasks if isinstance(f, CandidateFit)]
        per_run = iter(
            done_here
            or parallel_map(
                _folds_of,
                [(f, folds.test, folds.always_train, folds.by_set) for f in fits],
                jobs,
            )
        )
        for (label, spec, scale), done in tasks:
            scores: list[Score] = (
                [done] * n_folds if isinstance(done, ValueError) else next(per_run)
            )
            failed = next((s for s in scores if isinstance(s, ValueError)), None)
            if failed is not None:  # too few poses for this candidate in a fold
                say("auto", f"{label} (priors x{scale:g}) skipped: {failed}")
                continue
            cv = CrossValidation(spec.name, unit=folds.unit, notes=folds.notes)
            for tr, te in scores:  # type: ignore[misc]
                cv.train.append(tr)
                cv.folds.append(te)
            train = float(np.sqrt(np.mean([m.rms_mm**2 for m in cv.train])))
            say("auto", f"{label} (priors x{scale:g}): held-out RMS {cv.rms_mm:.4f} mm")
            cands.append(
                Candidate(
                    label,
                    spec,
                    scale,
                    CalibrationModel(robot, spec).size,
                    cv.rms_mm,
                    cv.rms_se_mm,
                    train,
                    fold_rms_mm=tuple(f.rms_mm for f in cv.folds),
                )
            )

    run([(label, spec, 1.0) for label, spec in layouts])
    if not cands:
        raise IdentifiabilityError(
            f"{meas.source}: no candidate model could be cross-validated: {meas.n} "
            f"poses in {n_folds} folds leave too few for even the kinematic model; "
            "measure more poses or give a fixed --model."
        )
    best = min(cands, key=lambda c: c.cv_rms_mm)
    if prior_scales is None:
        prior_scales = (1.0,) if opts.adapt_priors else (0.3, 1.0, 3.0)
    if opts.priors != "none":  # the best layout with other prior strengths
        run([(best.label, best.spec, s) for s in prior_scales if s != 1.0])
    best = min(cands, key=lambda c: c.cv_rms_mm)
    eligible = [c for c in cands if _within_one_se(c, best)]
    # Smallest model; among equal sizes the strongest priors (the simplest fit).
    chosen = min(eligible, key=lambda c: (c.size, -1.0 / c.prior_scale, c.cv_rms_mm))
    chosen.chosen = True
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
    spec = replace(chosen.spec, name=f"auto:{chosen.label}")
    return Selection(spec, chosen.prior_scale, cands, warnings, n_folds, shared)
