"""Train/test splits and k-fold cross-validation: folds by session, by pose, or by a
column of the user's, and the model comparison of the paper's Tables 5 and 8."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal._parallel import parallel_map
from kinecal._stats import first_rows, present
from kinecal.errors import DataError
from kinecal.identification._calibrate import CalibrationOptions, calibrate
from kinecal.identification._evaluate import evaluate, registered_model
from kinecal.measurement._calibrated import CalibratedModel
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._metrics import Metrics
from kinecal.models import ModelSpec
from kinecal.robot import RobotDescription, dh_transforms
from kinecal.typing import Float

__all__ = [
    "ComparisonRow",
    "CrossValidation",
    "Folds",
    "compare_models",
    "cross_validate",
    "cross_validate_many",
    "held_out_metrics",
    "kfold_indices",
    "make_folds",
    "pose_features",
    "region_labels",
    "relabel_sets",
    "sample_rows",
    "train_test_split",
]


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


# Above this many rows ``--cv`` and ``--model auto`` cross-validate a random sample of
# the poses (whole poses, every set kept): the 2K fold calibrations of ``--cv`` and the
# nominal robot's on a million rows took 200 s of CPU and 4 GB (issue 36), while the
# held-out figure of a model of a few dozen parameters hardly depends on the number of
# training rows beyond this (measured on 200 000 twin poses: docs/theory.md, "Accuracy
# on a new session").
CV_MAX_ROWS = 20_000
# Rows every set (session) and marker keeps in the sample: their frames are fitted.
_MIN_SET_ROWS = 50


@dataclass(frozen=True)
class Folds:
    """The folds of a cross-validation.

    Attributes
    ----------
    test : test-row indices of every fold.
    unit : what a fold holds whole: 'set' (sessions), 'region' (a region of joint space:
        what a new part of the workspace sees), 'pose' (rows measured at the same
        joints), 'row' or the name of the user's grouping column.
    always_train : (N,) bool, rows in the training data of every fold (markers with
        fewer rows than folds: a held-out row of theirs would have no tool offset).
    notes : what a user should know about the folds, in words.
    """

    test: list[np.ndarray]
    unit: str
    always_train: np.ndarray
    notes: tuple[str, ...] = ()

    @property
    def by_set(self) -> bool:
        return self.unit == "set"


def _member(values: np.ndarray, of: np.ndarray) -> np.ndarray:
    """``np.isin`` for non-negative integer labels (without numpy.ma)."""
    lut = np.zeros(max(int(values.max(initial=0)), int(of.max(initial=0))) + 1, bool)
    lut[of] = True
    return lut[values]


def region_labels(x: np.ndarray, k: int) -> np.ndarray:
    """A region (0..k-1) for every row of features ``x`` (N, m): k regions of about
    equal size, each a slab cut across the direction the rows spread most in (recursive
    bisection along the first principal axis, as a k-d tree does). Deterministic; equal
    rows share a region when they fall on one side of every cut."""
    x = np.asarray(x, float)
    out = np.zeros(x.shape[0], np.intp)

    def split(idx: np.ndarray, first: int, m: int) -> None:
        if m <= 1 or idx.size == 0:
            out[idx] = first
            return
        c = x[idx] - x[idx].mean(axis=0)
        if c.shape[1] == 0 or not np.any(c):
            proj = np.zeros(idx.size)
        else:
            v = np.linalg.svd(c, full_matrices=False)[2][0]
            proj = c @ (v if v[np.argmax(np.abs(v))] > 0 else -v)
        order = idx[np.argsort(proj, kind="stable")]
        m1 = m // 2
        n1 = round(idx.size * m1 / m)
        split(order[:n1], first, m1)
        split(order[n1:], first + m1, m - m1)

    split(np.arange(x.shape[0]), 0, k)
    return out


def pose_features(q_ctrl: np.ndarray, robot: RobotDescription | None = None) -> Float:
    """Where a pose is, as features for :func:`region_labels`: the nominal positions of
    the robot's joint frames and flange [m] (N, 3 (n + 1)), so the regions are parts of
    the workspace and arm configurations, weighted by how far each joint moves the arm
    (a wrist roll hardly); without ``robot`` the joint values, standardised."""
    q = np.asarray(q_ctrl, float)
    if robot is None:
        spread = q.std(axis=0)
        moving = spread > 1e-12
        return (q[:, moving] - q[:, moving].mean(axis=0)) / spread[moving]
    ch = robot.dh_chain()
    theta = robot.theta_from_ctrl(q)
    rot = np.where(ch.prismatic, ch.theta_offset, ch.theta_offset + theta)
    dd = np.where(ch.prismatic, ch.d + theta, ch.d)
    A = dh_transforms(rot, dd, ch.a, ch.alpha)  # (N, n, 4, 4)
    T = np.broadcast_to(ch.T_base_0, (q.shape[0], 4, 4)).copy()
    out = [T[:, :3, 3]]
    for i in range(robot.n_joints):  # loop over joints, not poses
        T = T @ A[:, i]
        out.append(T[:, :3, 3])
    out.append((T @ ch.T_n_flange)[:, :3, 3])
    return np.concatenate(out, axis=1)


SCHEMES = ("random", "region", "pose")


def make_folds(
    meas: Measurements,
    k: int,
    seed: int = 0,
    *,
    groups: np.ndarray | None = None,
    group_name: str = "group",
    scheme: str = "random",
    robot: RobotDescription | None = None,
) -> Folds:
    """k folds that never split what belongs together.

    Several sets: the folds are whole sets (their user frames are refitted when held
    out): what a new session sees. Otherwise whole groups: the user's ``groups`` (one
    label per row); with ``scheme='region'`` whole regions of joint space
    (:func:`region_labels` of :func:`pose_features`, of ``robot`` when given: each fold
    holds out a part of the workspace the training poses do not cover, as a new task
    would); by default (``'random'``) poses drawn at
    random (rows measured at the same joint values, as several reflectors of one pose,
    stay together): what new poses in the calibrated workspace see; ``'pose'`` is that
    even with several sets (all sets in every training set: the in-session figure).
    Rows of a marker with fewer rows than folds stay in every training set.

    Raises
    ------
    DataError
        Fewer groups than folds.
    """
    if k < 2:
        raise DataError(f"{meas.source}: cross-validation needs k >= 2 folds; got {k}.")
    if scheme not in SCHEMES:
        raise ValueError(f"scheme must be one of {SCHEMES}; got {scheme!r}.")
    n = meas.n
    always = np.zeros(n, bool)
    notes: list[str] = []
    if len(meas.set_labels) > 1 and groups is None and scheme != "pose":
        sets = present(meas.set_index)
        if sets.size < 2:
            raise DataError(f"{meas.source}: one set only; cannot fold by set.")
        k = min(k, sets.size)
        order = np.random.default_rng(seed).permutation(sets)
        test = [
            np.flatnonzero(_member(meas.set_index, chunk))
            for chunk in np.array_split(order, k)
        ]
        return Folds(test, "set", always)
    counts = np.bincount(meas.marker_index, minlength=len(meas.marker_labels))
    for m in np.flatnonzero((counts > 0) & (counts < k)):
        always |= meas.marker_index == m
        label = meas.marker_labels[m] or "(default)"
        notes.append(
            f"marker {label} has {counts[m]} rows, fewer than the {k} folds: they stay "
            "in the training data of every fold (a held-out row of theirs would have no "
            "tool offset to predict with)."
        )
    if groups is None:
        unit, g = "pose", meas.pose_groups()
        if scheme == "region":
            return _region_folds(meas, k, g, always, notes, robot)
    else:
        unit = group_name
        _, g = np.unique(np.asarray(groups).astype(str), return_inverse=True)
        g = g.reshape(-1)
    units = present(g[~always])
    if units.size < k:
        raise DataError(
            f"{meas.source}: {k}-fold cross-validation needs at least {k} "
            + (f"{unit}s" if groups is None else f"values of column {unit!r}")
            + f" to hold out; the data have {units.size}."
        )
    # Units in the order they first appear, so data whose rows are all different poses
    # fold exactly as rows do.
    first = first_rows(g)[units]
    units = units[np.argsort(first)]
    perm = np.random.default_rng(seed).permutation(units.size)
    test = [
        np.sort(np.flatnonzero(_member(g, units[chunk]) & ~always))
        for chunk in np.array_split(perm, k)
    ]
    if unit == "pose" and units.size < n - int(always.sum()):
        notes.append(
            f"{n} rows at {units.size} poses: rows of one pose fall in the same fold."
        )
    return Folds(test, unit, always, tuple(notes))


def _region_folds(
    meas: Measurements,
    k: int,
    g: np.ndarray,
    always: np.ndarray,
    notes: list[str],
    robot: RobotDescription | None,
) -> Folds:
    """Folds of whole regions of joint space (poses kept whole; see make_folds)."""
    units = present(g[~always])
    if units.size < k:
        raise DataError(
            f"{meas.source}: {k}-fold cross-validation needs at least {k} poses to "
            f"hold out; the data have {units.size}."
        )
    first = first_rows(np.where(always, g.max() + 1, g))[units]  # a row of every pose
    region = region_labels(pose_features(meas.q_ctrl[first], robot), k)
    of_unit = np.full(int(g.max()) + 1, -1, np.intp)
    of_unit[units] = region
    fold = of_unit[g]
    test = [np.flatnonzero((fold == i) & ~always) for i in range(k)]
    return Folds(test, "region", always, tuple(notes))


def kfold_indices(
    meas: Measurements, k: int, seed: int = 0, *, groups: np.ndarray | None = None
) -> list[np.ndarray]:
    """Test-row indices of k folds (:func:`make_folds`)."""
    return make_folds(meas, k, seed, groups=groups).test


@dataclass
class CrossValidation:
    """Per-fold held-out metrics and their mean."""

    model: str
    folds: list[Metrics] = field(default_factory=list)
    train: list[Metrics] = field(default_factory=list)
    unit: str = "row"  # what the folds hold whole (see Folds)
    notes: tuple[str, ...] = ()

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

    @property
    def norms_mm(self) -> np.ndarray | None:
        """The held-out 3-D error norm of every pose of every fold (mm), pooled; None
        when a fold's metrics do not keep them."""
        parts = [f.norms_mm for f in self.folds]
        if not parts or any(p is None for p in parts):
            return None
        return np.concatenate([p for p in parts if p is not None])


@one_blas_thread()
def cross_validate(
    robot: RobotDescription,
    meas: Measurements,
    model: str | ModelSpec = "full",
    *,
    k: int = 5,
    seed: int = 0,
    options: CalibrationOptions | None = None,
    jobs: int = 1,
    groups: np.ndarray | None = None,
    group_name: str = "group",
    scheme: str = "random",
) -> CrossValidation:
    """k-fold cross-validation (folds of :func:`make_folds`): with several sets the folds
    are whole sets and the user frame of a held-out set is refitted (a new set-up), as
    ``evaluate --refit user``; otherwise whole poses, or whole ``groups``.

    ``scheme='region'`` holds out whole regions of the workspace instead of random
    poses (see :func:`make_folds`). ``model='nominal'`` scores the nominal kinematics
    with fitted frames (the baseline).
    ``jobs`` > 1 calibrates the folds in that many worker processes
    (:func:`kinecal._parallel.parallel_map`); the result is the same.
    """
    (out,) = cross_validate_many(
        robot,
        meas,
        [(model, options)],
        k=k,
        seed=seed,
        jobs=jobs,
        groups=groups,
        group_name=group_name,
        scheme=scheme,
    )
    if isinstance(out, ValueError):
        raise out
    return out


@one_blas_thread()
def cross_validate_many(
    robot: RobotDescription,
    meas: Measurements,
    runs: list[tuple[str | ModelSpec, CalibrationOptions | None]],
    *,
    k: int = 5,
    seed: int = 0,
    jobs: int = 1,
    groups: np.ndarray | None = None,
    group_name: str = "group",
    scheme: str = "random",
) -> list[CrossValidation | ValueError]:
    """:func:`cross_validate` of several (model, options) runs on the same folds.

    All folds of all runs go to the workers at once, so ``jobs`` cores stay busy. A run
    whose calibration fails on some fold (too few poses for the model, say) gives the
    error of its first failing fold instead of a result.
    """
    folds = make_folds(
        meas, k, seed, groups=groups, group_name=group_name, scheme=scheme, robot=robot
    )
    tasks = [
        _Fold(robot, meas, model, options, test_idx, folds.unit)
        for model, options in runs
        for test_idx in folds.test
    ]
    done = iter(parallel_map(_run_fold, tasks, jobs))
    out: list[CrossValidation | ValueError] = []
    for model, _ in runs:
        cv = CrossValidation(
            model if isinstance(model, str) else model.name,
            unit=folds.unit,
            notes=folds.notes,
        )
        failed = None
        for _ in folds.test:
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
    unit: str

    @property
    def by_set(self) -> bool:
        return self.unit == "set"


def held_out_metrics(cal: CalibratedModel, test: Measurements, unit: str) -> Metrics:
    """A fold's held-out metrics: a held-out set (``unit='set'``: a new session) is
    scored after its user frame, which no training row saw, is registered anew on its
    own rows (``evaluate --refit user``); other folds as they are.

    Scoring held-out regions as new set-ups too (user and tool frames refitted on the
    region's poses) was tried (issue 31): it mended the FR3 halves (a to b: the
    kinematic model, the best, instead of the transmission terms at 1.09x) but a frame
    refitted on a small region also absorbs part of what the models differ in, and the
    choice became noisier: nested leave-one-out FR3 1.274 mm (kinematic 1.259; 1.166
    without), TIAGo 4.362 (kinematic 4.185; 4.187 without)."""
    if unit == "set":
        return evaluate(cal, test, refit=("user",)).metrics
    return evaluate(cal, test).metrics


def _run_fold(f: _Fold) -> tuple[Metrics, Metrics] | ValueError:
    """Training and held-out metrics of one fold (or the error that stopped it)."""
    mask = np.zeros(f.meas.n, bool)
    mask[f.test_idx] = True
    train, test = f.meas.subset(~mask), f.meas.subset(mask)
    if f.by_set:
        train = relabel_sets(train)
        test = relabel_sets(test)
    nominal = isinstance(f.model, str) and f.model == "nominal"
    try:
        res = calibrate(f.robot, train, "kinematic" if nominal else f.model, f.options)
    except ValueError as exc:
        return exc
    if nominal:
        return res.metrics_before, held_out_metrics(registered_model(res), test, f.unit)
    return res.metrics_after, held_out_metrics(res.calibrated, test, f.unit)


def relabel_sets(meas: Measurements) -> Measurements:
    """Keep only the set labels that occur (after a split)."""
    used = present(meas.set_index)
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


@one_blas_thread()
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


def sample_rows(
    meas: Measurements, groups: np.ndarray | None, seed: int
) -> tuple[Measurements, np.ndarray | None, str]:
    """About :data:`CV_MAX_ROWS` rows of ``meas`` drawn at random by whole poses (every
    row of a pose kept or left alike; every set and every marker keeps at least
    :data:`_MIN_SET_ROWS` rows, or all of its own), ``groups`` cut alike, and the note
    that says so."""
    pose = meas.pose_groups()
    u = np.random.default_rng([seed, 36]).random(int(pose.max()) + 1)
    key = u[pose]
    keep = key < CV_MAX_ROWS / meas.n
    for index, labels in (
        (meas.set_index, meas.set_labels),
        (meas.marker_index, meas.marker_labels),
    ):
        for s in range(len(labels)):
            rows = np.flatnonzero(index == s) if index.size else np.arange(meas.n)
            if 0 < rows.size and np.count_nonzero(keep[rows]) < _MIN_SET_ROWS:
                # few rows of a set (or marker): its first rows in the random order
                last = np.sort(key[rows])[min(_MIN_SET_ROWS, rows.size) - 1]
                keep[rows] |= key[rows] <= last
    rows = np.flatnonzero(keep)
    note = (
        f"cross-validated on {rows.size} of the {meas.n} rows, drawn at random by "
        f"whole poses (above {CV_MAX_ROWS} rows the held-out figures hardly change "
        "with more training rows, and each fold is a calibration)"
    )
    return meas.subset(rows), None if groups is None else groups[rows], note
