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
    cal, found, _ = _refit(calibrated, meas, groups, names)
    return cal, found


def _refit(
    calibrated: CalibratedModel,
    meas: Measurements,
    groups: tuple[str, ...],
    names: list[str] | None,
) -> tuple[CalibratedModel, list[Diagnostic], Measurements]:
    """:func:`refit_diagnosed`, and the data relabelled to the refitted model's sets
    and markers (:func:`session_model`)."""
    old = calibrated.model
    solve = (
        tuple("cam" if g == "marker" else g for g in groups) if names is None else ()
    )
    model, x, status, std, m = session_model(
        calibrated, meas, new_sets="base" in solve, new_markers="cam" in solve
    )
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
    return cal, list(reg.diagnostics), m


# A marker the model lacks gets its offset fitted on at least this many distinct poses
# (as a set's user frame: fewer, and the refitted offset absorbs their errors).
NEW_MARKER_POSES = 3
_HINTS = {
    "set": " Use --refit user for a new set-up.",
    "marker": " Use --refit marker (or tool) for a new marker: its offset is then "
    "fitted on these rows.",
}


def session_model(
    calibrated: CalibratedModel,
    meas: Measurements,
    *,
    new_sets: bool = False,
    new_markers: bool = False,
) -> tuple[CalibrationModel, Float, list[str], Float, Measurements]:
    """The calibrated model on the sets and markers of ``meas``, and the data
    relabelled to it (model, parameters, status, std, data).

    Sets: the model's sets the data have rows of (a set the data lack is left out: its
    closed form failed on no rows, "set 'A' has 0 rows"); with ``new_sets`` (the user
    frames are refitted: a new set-up) the data's own sets, whatever their labels.
    Markers: the model's; with ``new_markers`` (the cam frames or marker offsets are
    refitted) and a marker the model lacks (a new SMR or probe), that marker is added,
    started from the first marker's frame (its rotation: markers are points on one
    tool), its offset to be fitted on its rows. A frame kept carries its parameters,
    status, std and reference rotation over by name.

    Raises
    ------
    DataError
        A set or marker the model lacks, its frame not refitted (the message names
        the ``--refit`` that fits it).
    IdentifiabilityError
        A new marker seen in fewer than :data:`NEW_MARKER_POSES` distinct poses.
    """
    old = calibrated.model
    spec = old.spec
    sets, s_idx, R_base = _sets(meas, spec.sets, old.R_ref_base, new_sets)
    markers, m_idx, R_cam = _markers(meas, spec.markers, old.R_ref_cam, new_markers)
    m = replace(
        meas,
        set_index=s_idx,
        set_labels=sets,
        marker_index=m_idx,
        marker_labels=markers,
    )
    x, status, std = calibrated.params, list(calibrated.status), calibrated.std
    if sets == spec.sets and markers == spec.markers and R_base is old.R_ref_base:
        return old, x.copy(), status, std.copy(), m
    model = CalibrationModel(
        old.robot, replace(spec, sets=sets, markers=markers)
    ).with_references(R_base, R_cam if spec.cam_rotation else None)
    status = [
        status[old.layout.index(n)] if n in old.layout else "estimated"
        for n in model.layout.names
    ]
    x, std = (
        model.layout.transfer(x, old.layout),
        model.layout.transfer(std, old.layout),
    )
    new = model.cam_index[len(spec.markers) :]  # added markers: the first one's frame
    first = model.cam_index[0]
    x[new], std[new] = x[first], std[first]  # (its rotation: points on one tool)
    for i, k in zip(new.ravel(), np.broadcast_to(first, new.shape).ravel()):
        status[i] = status[k]
    return model, x, status, std, m


def _sets(
    meas: Measurements, own: tuple[str, ...], R_ref: Float, new: bool
) -> tuple[tuple[str, ...], np.ndarray, Float]:
    """The sets of the model fitted to ``meas`` (``own``: the model's, ``R_ref`` their
    reference rotations), each row's index into them and their reference rotations."""
    from kinecal.measurement._calibrated import map_labels

    labels, index = meas.set_labels, meas.set_index
    if new and tuple(labels) != own:  # a new set-up: the data's sets, as labelled
        used = np.unique(index)
        remap = np.full(len(labels), -1, np.intp)
        remap[used] = np.arange(used.size)
        eye = np.broadcast_to(np.eye(3), (used.size, 3, 3))
        return tuple(labels[i] for i in used), remap[index], eye
    idx = map_labels(labels, index, own, "set", meas.source, hint=_HINTS["set"])
    keep = np.unique(idx)
    if keep.size == len(own):
        return own, idx, R_ref
    remap = np.full(len(own), -1, np.intp)
    remap[keep] = np.arange(keep.size)
    return tuple(own[i] for i in keep), remap[idx], R_ref[keep]


def _markers(
    meas: Measurements, own: tuple[str, ...], R_ref: Float, new: bool
) -> tuple[tuple[str, ...], np.ndarray, Float]:
    """The markers of the model fitted to ``meas`` (``own``: the model's, ``R_ref``
    their reference rotations), each row's index into them and their reference
    rotations; ``new``: markers the model lacks are added (identity reference)."""
    from kinecal.errors import DataError
    from kinecal.measurement._calibrated import map_labels

    labels, index = meas.marker_labels, meas.marker_index
    try:
        idx = map_labels(
            labels, index, own, "marker", meas.source, hint=_HINTS["marker"]
        )
        return own, idx, R_ref
    except DataError:
        if not new:
            raise
    used = [labels[i] for i in np.unique(index)]
    added = tuple(lab for lab in used if lab not in own)
    out = own + added
    idx = np.array([out.index(lab) for lab in labels], np.intp)[index]
    _check_new_markers(meas, added, out, idx)
    first = np.broadcast_to(R_ref[0], (len(added), 3, 3))
    return out, idx, np.concatenate([R_ref, first])


def _check_new_markers(
    meas: Measurements, added: tuple[str, ...], labels: tuple[str, ...], idx: np.ndarray
) -> None:
    """Refuse a new marker (of ``added``) seen in fewer than :data:`NEW_MARKER_POSES`
    distinct poses: its offset, fitted on them, would match them (an RMS of about 0)."""
    from kinecal._stats import distinct_rows
    from kinecal.errors import IdentifiabilityError

    for label in added:
        rows = idx == labels.index(label)
        n = distinct_rows(meas.q_ctrl[rows])
        if n < NEW_MARKER_POSES:
            raise IdentifiabilityError(
                f"{meas.source}: marker {label!r} is not in the model, so its offset is "
                f"fitted on its rows, but they hold {n} distinct pose"
                f"{'s' if n != 1 else ''} ({int(rows.sum())} rows); a new marker needs "
                f"at least {NEW_MARKER_POSES} (measure it at more poses, or leave its "
                "rows out)."
            )


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
    cal, m = calibrated, meas
    if what:
        groups = tuple(REFIT_GROUPS[w] for w in what)
        cal, found, m = _refit(calibrated, meas, groups, None)
    else:  # a set or marker the model lacks: the message names the --refit for it
        spec, model = calibrated.model.spec, calibrated.model
        _sets(meas, spec.sets, model.R_ref_base, False)
        _markers(meas, spec.markers, model.R_ref_cam, False)
    blk = cal.predict(m)
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
