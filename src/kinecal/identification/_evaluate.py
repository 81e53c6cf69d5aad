"""Held-out evaluation, user-frame refit, train/test split and k-fold cross-validation."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._parallel import parallel_map
from kinecal.identification._calibrate import (
    CalibrationOptions,
    CalibrationResult,
    calibrate,
)
from kinecal.identification._calibrated import CalibratedModel
from kinecal.identification._diagnostics import Diagnostic
from kinecal.identification._measurements import Measurements
from kinecal.identification._metrics import Metrics, metrics_from_errors
from kinecal.identification._registration import register
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = [
    "CrossValidation",
    "Evaluation",
    "cross_validate",
    "cross_validate_many",
    "evaluate",
    "kfold_indices",
    "refit",
    "refit_diagnosed",
    "registered_model",
    "train_test_split",
]


@dataclass
class Evaluation:
    """Errors of a calibrated model on a data set."""

    metrics: Metrics
    errors_mm: Float  # (N,) 3-D error norms
    error_xyz_mm: Float  # (N, 3) model minus measurement, user frame
    calibrated: CalibratedModel  # the model used (after any refit)
    diagnostics: list[Diagnostic] = field(default_factory=list)  # of the refit


def refit(
    calibrated: CalibratedModel,
    meas: Measurements,
    groups: tuple[str, ...] = ("base",),
    *,
    names: list[str] | None = None,
) -> CalibratedModel:
    """Re-estimate some parameters of a calibration on new data, the rest held.

    With ``groups=('base',)`` this registers new user frames: one per set of ``meas``
    (a new tracker set-up), started in closed form (:mod:`._registration`, the path
    calibration and cross-validation take too); ``'cam'`` does the same for the cam
    frames (a re-mounted probe). Findings of the registration (a set whose points do not
    fix its rotation) are issued as warnings.

    Parameters
    ----------
    calibrated : CalibratedModel
    meas : Measurements
    groups : parameter groups to re-estimate ('base', 'cam', 'joint', 'ntm', ...).
    names : exact parameter names to re-estimate instead of groups (only those move).
    """
    cal, found = refit_diagnosed(calibrated, meas, groups, names=names)
    for d in found:
        if d.severity == "warning":
            warnings.warn(d.message, stacklevel=2)
    return cal


def refit_diagnosed(
    calibrated: CalibratedModel,
    meas: Measurements,
    groups: tuple[str, ...] = ("base",),
    *,
    names: list[str] | None = None,
) -> tuple[CalibratedModel, list[Diagnostic]]:
    """:func:`refit`, returning its diagnostics instead of warning."""
    old = calibrated.model
    spec = old.spec
    solve = groups if names is None else ()
    new_sets = "base" in solve and tuple(meas.set_labels) != tuple(spec.sets)
    if new_sets:
        model = CalibrationModel(old.robot, replace(spec, sets=meas.set_labels))
        model = model.with_references(
            None, old.R_ref_cam if spec.cam_rotation else None
        )
        x = model.layout.transfer(calibrated.params, old.layout)
        status = [
            calibrated.status[old.layout.index(n)] if n in old.layout else "estimated"
            for n in model.layout.names
        ]
        std = model.layout.transfer(calibrated.std, old.layout)
        m = meas
    else:
        model, x = old, calibrated.params.copy()
        status, std = list(calibrated.status), calibrated.std.copy()
        m = calibrated.align(meas)
    layout = model.layout
    if names is None:
        free = np.isin([s.group for s in layout.specs], groups)
    else:
        unknown = [n for n in names if n not in layout]
        if unknown:
            raise ValueError(
                f"refit: unknown parameter {unknown[0]!r}; the model has "
                f"{layout.size} parameters (see its layout)."
            )
        free = np.isin(layout.names, names)
    free &= np.array([st != "unidentifiable" for st in status])
    reg = register(
        model,
        x,
        m,
        free,
        groups=solve,
        inputs=m.model_inputs(calibrated.reference_payload_kg),
    )
    cal = CalibratedModel(
        reg.model,
        reg.x,
        std,
        status,
        calibrated.reference_payload_kg,
        info={**calibrated.info, "refit": list(groups) if names is None else names},
    )
    return cal, list(reg.diagnostics)


def evaluate(
    calibrated: CalibratedModel, meas: Measurements, *, refit_user: bool = False
) -> Evaluation:
    """Accuracy of a calibrated model on (held-out) data.

    Parameters
    ----------
    refit_user : bool
        Re-estimate only the user frame(s) on ``meas`` first: the data come from a new
        tracker set-up (DESIGN §11).
    """
    found: list[Diagnostic] = []
    cal = calibrated
    if refit_user:
        cal, found = refit_diagnosed(calibrated, meas, ("base",))
    blk = cal.predict(meas)
    met = metrics_from_errors(blk.raw_position, blk.raw_rotation)
    return Evaluation(
        met,
        np.linalg.norm(blk.raw_position, axis=1) * 1e3,
        blk.raw_position * 1e3,
        cal,
        found,
    )


def train_test_split(
    meas: Measurements, n_train: int | float, seed: int = 0
) -> tuple[Measurements, Measurements]:
    """Random split into ``n_train`` rows (or that fraction) and the rest."""
    n = meas.n
    k = (
        round(n_train * n)
        if isinstance(n_train, float) and n_train < 1
        else int(n_train)
    )
    if not 0 < k < n:
        raise ValueError(
            f"n_train must leave rows on both sides; got {n_train} of {n}."
        )
    perm = np.random.default_rng(seed).permutation(n)
    return meas.subset(np.sort(perm[:k])), meas.subset(np.sort(perm[k:]))


def kfold_indices(
    meas: Measurements, k: int, seed: int = 0, *, by_set: bool = True
) -> list[np.ndarray]:
    """Test-row indices of k folds; grouped by set (session) when there are several."""
    if by_set and len(meas.set_labels) > 1:
        sets = np.unique(meas.set_index)
        k = min(k, sets.size)
        order = np.random.default_rng(seed).permutation(sets)
        return [
            np.flatnonzero(np.isin(meas.set_index, chunk))
            for chunk in np.array_split(order, k)
        ]
    if k < 2 or k > meas.n:
        raise ValueError(
            f"k must be between 2 and the number of rows ({meas.n}); got {k}."
        )
    perm = np.random.default_rng(seed).permutation(meas.n)
    return [np.sort(chunk) for chunk in np.array_split(perm, k)]


@dataclass
class CrossValidation:
    """Per-fold held-out metrics and their mean."""

    model: str
    folds: list[Metrics] = field(default_factory=list)
    train: list[Metrics] = field(default_factory=list)

    @property
    def rms_mm(self) -> float:
        """Pooled held-out RMS over all folds."""
        num = sum(f.rms_mm**2 * f.n for f in self.folds)
        return float(np.sqrt(num / max(sum(f.n for f in self.folds), 1)))

    @property
    def rms_se_mm(self) -> float:
        """Standard error of the fold RMS values."""
        v = np.array([f.rms_mm for f in self.folds])
        return float(v.std(ddof=1) / np.sqrt(v.size)) if v.size > 1 else float("nan")


def cross_validate(
    robot: RobotDescription,
    meas: Measurements,
    model: str | ModelSpec = "full",
    *,
    k: int = 5,
    seed: int = 0,
    options: CalibrationOptions | None = None,
    jobs: int = 1,
) -> CrossValidation:
    """k-fold cross-validation; with several sets the folds are whole sets and the user
    frame of a held-out set is refitted (a new set-up), as ``evaluate --refit user``.

    ``model='nominal'`` scores the nominal kinematics with fitted frames (the baseline).
    ``jobs`` > 1 calibrates the folds in that many worker processes
    (:func:`kinecal._parallel.parallel_map`); the result is the same.
    """
    (out,) = cross_validate_many(
        robot, meas, [(model, options)], k=k, seed=seed, jobs=jobs
    )
    if isinstance(out, ValueError):
        raise out
    return out


def cross_validate_many(
    robot: RobotDescription,
    meas: Measurements,
    runs: list[tuple[str | ModelSpec, CalibrationOptions | None]],
    *,
    k: int = 5,
    seed: int = 0,
    jobs: int = 1,
) -> list[CrossValidation | ValueError]:
    """:func:`cross_validate` of several (model, options) runs on the same folds.

    All folds of all runs go to the workers at once, so ``jobs`` cores stay busy. A run
    whose calibration fails on some fold (too few poses for the model, say) gives the
    error of its first failing fold instead of a result.
    """
    folds = kfold_indices(meas, k, seed)
    by_set = len(meas.set_labels) > 1 and len(folds) == len(np.unique(meas.set_index))
    tasks = [
        _Fold(robot, meas, model, options, test_idx, by_set)
        for model, options in runs
        for test_idx in folds
    ]
    done = iter(parallel_map(_run_fold, tasks, jobs))
    out: list[CrossValidation | ValueError] = []
    for model, _ in runs:
        cv = CrossValidation(model if isinstance(model, str) else model.name)
        failed = None
        for _ in folds:
            res = next(done)
            if isinstance(res, ValueError):
                failed = failed or res
                continue
            cv.train.append(res[0])
            cv.folds.append(res[1])
        out.append(failed if failed is not None else cv)
    return out


@dataclass(frozen=True)
class _Fold:
    """One fold of one cross-validation run (sent to a worker process)."""

    robot: RobotDescription
    meas: Measurements
    model: str | ModelSpec
    options: CalibrationOptions | None
    test_idx: np.ndarray
    by_set: bool


def _run_fold(f: _Fold) -> tuple[Metrics, Metrics] | ValueError:
    """Training and held-out metrics of one fold (or the error that stopped it)."""
    mask = np.zeros(f.meas.n, bool)
    mask[f.test_idx] = True
    train, test = f.meas.subset(~mask), f.meas.subset(mask)
    if f.by_set:
        train = _relabel_sets(train)
        test = _relabel_sets(test)
    nominal = isinstance(f.model, str) and f.model == "nominal"
    try:
        res = calibrate(f.robot, train, "kinematic" if nominal else f.model, f.options)
    except ValueError as exc:
        return exc
    if nominal:
        return res.metrics_before, evaluate(
            registered_model(res), test, refit_user=f.by_set
        ).metrics
    return res.metrics_after, evaluate(
        res.calibrated, test, refit_user=f.by_set
    ).metrics


def registered_model(res: CalibrationResult) -> CalibratedModel:
    """The state before calibration: nominal kinematics with the fitted user and cam
    frames of ``res`` (what a 'nominal' row scores)."""
    cal = res.calibrated
    return CalibratedModel(
        cal.model,
        res.registered,
        np.full(cal.model.size, np.nan),
        ["fixed"] * cal.model.size,
        cal.reference_payload_kg,
    )


def _relabel_sets(meas: Measurements) -> Measurements:
    """Keep only the set labels that occur (after a split)."""
    used = np.unique(meas.set_index)
    remap = -np.ones(len(meas.set_labels), np.intp)
    remap[used] = np.arange(used.size)
    return replace(
        meas,
        set_index=remap[meas.set_index],
        set_labels=tuple(meas.set_labels[i] for i in used),
    )


@dataclass
class ComparisonRow:
    """One row of a Table 5/8-style comparison (test metrics on held-out data)."""

    model: str
    size: int
    n_free: int
    train: Metrics
    test: Metrics
    seconds: float
    calibrated: CalibratedModel | None = None
    result: object | None = None  # the CalibrationResult (None for the nominal row)


def compare_models(
    robot: RobotDescription,
    train: Measurements,
    test: Measurements,
    models: tuple[str | ModelSpec, ...] = ("kinematic", "ntm", "rfcm", "full"),
    *,
    options: CalibrationOptions | None = None,
    refit_user: bool = False,
    nominal: bool = True,
    progress: object | None = None,
) -> list[ComparisonRow]:
    """Calibrate each model on ``train`` and score it on ``test`` (Tables 5 and 8).

    With ``nominal`` a first row scores the nominal kinematics with fitted user and cam
    frames (the state before calibration).
    """
    rows: list[ComparisonRow] = []
    say = progress if callable(progress) else (lambda stage, detail: None)
    for spec in models:
        name = spec if isinstance(spec, str) else spec.name
        say("compare", name)
        res = calibrate(robot, train, spec, options)
        cal = res.calibrated
        if nominal and not rows:
            before = registered_model(res)
            rows.append(
                ComparisonRow(
                    "nominal",
                    int(
                        len(before.model.base_index.ravel())
                        + before.model.cam_index.size
                    ),
                    int(
                        len(before.model.base_index.ravel())
                        + before.model.cam_index.size
                    ),
                    res.metrics_before,
                    evaluate(before, test, refit_user=refit_user).metrics,
                    0.0,
                    before,
                    None,
                )
            )
        rows.append(
            ComparisonRow(
                name,
                cal.model.size,
                res.identifiability.rank,
                res.metrics_after,
                evaluate(cal, test, refit_user=refit_user).metrics,
                res.seconds,
                cal,
                res,
            )
        )
    return rows
