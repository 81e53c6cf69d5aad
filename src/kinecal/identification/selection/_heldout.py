"""Held-out accuracy as a new session sees it (``calibrate --cv K``).

One calibration is judged by what it predicts on poses it was not fitted on, and two
figures say different things: poses drawn at random from the calibrated workspace (the
*in-session* figure, what most tools report) and whole regions of the workspace held out,
or whole sessions when the data have several (the *new-region* / *new-session* figure,
what a new task or the next set-up of the tracker sees). Both come from the one
cross-validation path of ``--model auto`` (:func:`~kinecal.identification.
cross_validate_models`), so the same folds give the same figures; the nominal robot with
fitted frames is scored on the same folds as the baseline.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal.identification._calibrate import CalibrationOptions
from kinecal.identification.selection import _crossval
from kinecal.identification.selection._crossval import (
    CrossValidation,
    Folds,
    cross_validate_many,
    make_folds,
)
from kinecal.identification.selection._select import (
    Selection,
    cross_validate_models,
)
from kinecal.measurement._measurements import Measurements
from kinecal.models import ModelSpec
from kinecal.robot import RobotDescription

__all__ = ["HeldOutAccuracy", "HeldOutFigure", "held_out_accuracy"]


# What each kind of fold imitates, in words (the report's and the console's names).
_NAMES = {
    "pose": "in-session",
    "region": "new region",
    "set": "new session",
}


@dataclass(frozen=True)
class HeldOutFigure:
    """The model's and the nominal robot's cross-validation on one kind of folds.

    Attributes
    ----------
    name : 'in-session' (random poses), 'new region' (regions of the workspace),
        'new session' (whole sets) or 'groups' (the user's column).
    folds : the folds.
    model, nominal : the cross-validations of the calibrated and the nominal model.
    """

    name: str
    folds: Folds
    model: CrossValidation
    nominal: CrossValidation

    def as_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "unit": self.folds.unit,
            "folds": len(self.folds.test),
            "notes": list(self.folds.notes),
            "model": _cv_dict(self.model),
            "nominal": _cv_dict(self.nominal),
        }


@dataclass(frozen=True)
class HeldOutAccuracy:
    """The held-out figures of one calibration (:func:`held_out_accuracy`).

    Attributes
    ----------
    figures : the in-session figure first, then the new-region or new-session one
        (one figure only with the user's groups).
    notes : what the figures cannot tell, in words (one session: a new set-up).
    """

    k: int
    figures: tuple[HeldOutFigure, ...]
    notes: tuple[str, ...]

    def figure(self, name: str) -> HeldOutFigure | None:
        return next((f for f in self.figures if f.name == name), None)

    @property
    def transfer(self) -> HeldOutFigure:
        """The figure that imitates a new session (the last one)."""
        return self.figures[-1]

    def as_dict(self) -> dict[str, Any]:
        """report.json's ``cross_validation``: every figure by name, and at the top the
        figure of :func:`make_folds`' default folds (whole sets when there are several,
        else random poses), as earlier releases wrote it."""
        legacy = self.figure("new session") or self.figures[0]
        out: dict[str, Any] = {
            "folds": self.k,
            "unit": legacy.folds.unit,
            "notes": list(legacy.folds.notes),
            "model": _cv_dict(legacy.model),
            "nominal": _cv_dict(legacy.nominal),
            "figures": {f.name: f.as_dict() for f in self.figures},
            "advice": list(self.notes),
        }
        return out


def _cv_dict(cv: CrossValidation) -> dict[str, Any]:
    n = sum(f.n for f in cv.folds)
    xyz = [
        float(np.sqrt(sum(f.n * f.rms_xyz_mm[a] ** 2 for f in cv.folds) / max(n, 1)))
        for a in range(3)
    ]
    out: dict[str, Any] = {
        "rms_mm": cv.rms_mm,
        "se_mm": cv.rms_se_mm,
        "rms_xyz_mm": xyz,
        "fold_rms_mm": [f.rms_mm for f in cv.folds],
        "train_rms_mm": [f.rms_mm for f in cv.train],
    }
    d = cv.norms_mm  # every held-out pose of every fold: Std, Avg, Max as Table 5's
    if d is not None and d.size:
        out |= {"std_mm": float(d.std()), "mean_mm": float(d.mean())}
        out["max_mm"] = float(d.max())
    rot = [f.rot_rms_deg for f in cv.folds]
    if cv.folds and all(r is not None for r in rot):
        out["rot_rms_deg"] = float(
            np.sqrt(
                sum(f.n * (f.rot_rms_deg or 0.0) ** 2 for f in cv.folds) / max(n, 1)
            )
        )
        out["rot_max_deg"] = max(float(f.rot_max_deg or 0.0) for f in cv.folds)
    return out


@one_blas_thread()
def held_out_accuracy(
    robot: RobotDescription,
    meas: Measurements,
    spec: ModelSpec,
    k: int,
    *,
    options: CalibrationOptions | None = None,
    seed: int = 0,
    groups: np.ndarray | None = None,
    group_name: str = "group",
    selection: Selection | None = None,
    jobs: int = 1,
    progress: object | None = None,
) -> HeldOutAccuracy:
    """Cross-validated held-out errors of ``spec`` (and of the nominal robot) on random
    poses and on whole regions of the workspace (or whole sessions when ``meas`` has
    several sets; the user's ``groups`` alone when given).

    With ``selection`` (``--model auto``) the chosen candidate is scored by the
    selection's own fits: on the folds it was chosen with, its table's figures. Above
    :data:`~kinecal.identification.selection._crossval.CV_MAX_ROWS` rows the folds are
    those of a random sample of whole poses (the selection's own), as the folds' notes
    say.

    Raises
    ------
    ValueError
        A fold whose training rows cannot determine the model (the error of the first).
    """
    opts = options or CalibrationOptions()
    sampled = None
    got = None if selection is None else selection.sample
    if got is not None and got[3] == seed:  # the selection's sample: drawn once
        meas, groups, sampled = got[:3]
    elif meas.n > _crossval.CV_MAX_ROWS:  # (the selection's own sample, when it ran)
        meas, groups, sampled = _crossval.sample_rows(meas, groups, seed)
    kw: dict[str, Any] = {"groups": groups, "group_name": group_name}
    if groups is not None:
        schemes = [("groups", "random")]
    else:
        new = "new session" if len(meas.set_labels) > 1 else "new region"
        schemes = [("in-session", "pose"), (new, "region")]
    folds = [make_folds(meas, k, seed, scheme=s, robot=robot, **kw) for _, s in schemes]
    if selection is not None:
        models: list[CrossValidation | ValueError] = [
            selection.chosen_cv(f) for f in folds
        ]
    else:
        models = cross_validate_models(
            robot,
            meas,
            [(spec.name, spec)],
            folds,
            options=opts,
            jobs=jobs,
            progress=progress,
        )
    figures = []
    for (name, scheme), f, model in zip(schemes, folds, models, strict=True):
        if isinstance(model, ValueError):
            raise model
        (nominal,) = cross_validate_many(
            robot,
            meas,
            [("nominal", opts)],
            k=k,
            seed=seed,
            jobs=jobs,
            scheme=scheme,
            **kw,
        )
        if isinstance(nominal, ValueError):
            raise nominal
        if sampled is not None:
            f = replace(f, notes=(*f.notes, sampled))
        figures.append(HeldOutFigure(_NAMES.get(f.unit, name), f, model, nominal))
    notes = []
    if len(meas.set_labels) <= 1:
        notes.append(
            "one session: these figures cannot tell the error of a new set-up (the "
            "tracker or the part moved, the tool re-mounted): its frames are fitted "
            "here. Measure a second session and score it with `kinecal evaluate "
            "--refit user,tool`, or calibrate on several sessions (a set column) for a "
            "new-session figure."
        )
    return HeldOutAccuracy(k, tuple(figures), tuple(notes))
