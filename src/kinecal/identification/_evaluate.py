"""Held-out evaluation and the refit of a calibration on a new session."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal.identification._calibrate import (
    CalibrationResult,
)
from kinecal.identification._registration import register
from kinecal.measurement._calibrated import CalibratedModel
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._metrics import Metrics, metrics_from_errors
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = [
    "Evaluation",
    "evaluate",
    "refit",
    "refit_diagnosed",
    "registered_model",
]


@dataclass
class Evaluation:
    """Errors of a calibrated model on a data set."""

    metrics: Metrics
    errors_mm: Float  # (N,) 3-D error norms
    error_xyz_mm: Float  # (N, 3) model minus measurement, user frame
    calibrated: CalibratedModel  # the model used (after any refit)
    diagnostics: list[Diagnostic] = field(default_factory=list)  # of the refit


@one_blas_thread()
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
    frames (a re-mounted probe or reflector nest: every marker's frame, its rotation
    too for pose data), ``'marker'`` for each marker's offset (the cam-frame
    translations). Findings of the registration (a set whose points do not fix its
    rotation, orientations that differ by a common rotation) are issued as warnings.

    Parameters
    ----------
    calibrated : CalibratedModel
    meas : Measurements
    groups : parameter groups to re-estimate ('base', 'cam', 'marker', 'joint', ...).
    names : exact parameter names to re-estimate instead of groups (only those move).
    """
    cal, found = refit_diagnosed(calibrated, meas, groups, names=names)
    for d in found:
        if d.severity == "warning":
            warnings.warn(d.message, stacklevel=2)
    return cal


@one_blas_thread()
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
    solve = (
        tuple("cam" if g == "marker" else g for g in groups) if names is None else ()
    )
    new_sets = "base" in solve and tuple(meas.set_labels) != tuple(spec.sets)
    if new_sets:
        model, x, status, std = _on_sets(calibrated, tuple(meas.set_labels), None)
        m = meas
    else:
        m = calibrated.align(meas)
        used = np.unique(m.set_index)
        if used.size == len(spec.sets):
            model, x = old, calibrated.params.copy()
            status, std = list(calibrated.status), calibrated.std.copy()
        else:  # a tool or marker refit of the data of some of the model's sets
            model, x, status, std, m = _present_sets(calibrated, m, used)
    layout = model.layout
    if names is None:
        free = np.isin([s.group for s in layout.specs], groups)
        if "marker" in groups:  # each marker's offset: the cam-frame translations
            free[layout.select(group="cam", field=("x", "y", "z"))] = True
    else:
        from kinecal.robot._param_names import canonical_parameter_name

        names = [canonical_parameter_name(n, old.robot.joint_names) for n in names]
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


def _on_sets(
    calibrated: CalibratedModel, sets: tuple[str, ...], R_ref_base: Float | None
) -> tuple[CalibrationModel, Float, list[str], Float]:
    """The calibrated model with the user frames ``sets`` (reference rotations
    ``R_ref_base``, None: the identity): parameters, status and std carried over by
    name, a new set's frame 'estimated' at 0."""
    old = calibrated.model
    spec = old.spec
    model = CalibrationModel(old.robot, replace(spec, sets=sets)).with_references(
        R_ref_base, old.R_ref_cam if spec.cam_rotation else None
    )
    status = [
        calibrated.status[old.layout.index(n)] if n in old.layout else "estimated"
        for n in model.layout.names
    ]
    return (
        model,
        model.layout.transfer(calibrated.params, old.layout),
        status,
        model.layout.transfer(calibrated.std, old.layout),
    )


def _present_sets(
    calibrated: CalibratedModel, meas: Measurements, used: np.ndarray
) -> tuple[CalibrationModel, Float, list[str], Float, Measurements]:
    """The model restricted to the sets ``used`` (indices of the model's sets that
    ``meas``, aligned to it, has rows of), and the data relabelled to it: a tool or
    marker refit of the data of one session of a model calibrated on several needs no
    frame of the others (their closed form failed on their empty rows: "set 'A' has 0
    rows"). As a refit of the user frames does, the refitted model then holds the
    data's sets."""
    old = calibrated.model
    keep = tuple(old.spec.sets[i] for i in used)
    model, x, status, std = _on_sets(calibrated, keep, old.R_ref_base[used])
    remap = np.full(len(old.spec.sets), -1, np.intp)
    remap[used] = np.arange(used.size)
    m = replace(meas, set_index=remap[meas.set_index], set_labels=keep)
    return model, x, status, std, m


REFIT_GROUPS = {"user": "base", "tool": "cam", "marker": "marker"}


@one_blas_thread()
def evaluate(
    calibrated: CalibratedModel,
    meas: Measurements,
    *,
    refit_user: bool = False,
    refit: tuple[str, ...] = (),
) -> Evaluation:
    """Accuracy of a calibrated model on (held-out) data.

    Parameters
    ----------
    refit_user : bool
        Re-estimate only the user frame(s) on ``meas`` first: the data come from a new
        tracker set-up (``refit=('user',)``).
    refit : what to re-estimate on ``meas`` first: any of 'user' (the user frames: a new
        instrument set-up), 'tool' (the tool frame: a re-mounted probe or reflector nest)
        and 'marker' (each marker's offset).
    """
    what = tuple(refit) + (("user",) if refit_user and "user" not in refit else ())
    unknown = [w for w in what if w not in REFIT_GROUPS]
    if unknown:
        raise ValueError(
            f"refit takes 'user', 'tool' and 'marker'; got {unknown[0]!r}."
        )
    found: list[Diagnostic] = []
    cal = calibrated
    if what:
        groups = tuple(REFIT_GROUPS[w] for w in what)
        cal, found = refit_diagnosed(calibrated, meas, groups)
    blk = cal.predict(meas)
    met = metrics_from_errors(blk.raw_position, blk.raw_rotation)
    return Evaluation(
        met,
        np.linalg.norm(blk.raw_position, axis=1) * 1e3,
        blk.raw_position * 1e3,
        cal,
        found,
    )


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
