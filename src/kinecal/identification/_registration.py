"""Registration: the user and tool frames of a data set, the rest of the model held.

One path serves calibration (every frame, from nominal kinematics), refit on a new
session (``--refit user``: the user frames; ``tool``: the cam frames) and the held-out
sets of cross-validation:

1. a closed-form start (:func:`initial_registration`): Kabsch/Umeyama of the model's
   points in the robot base frame onto the measurements for the user frames alone, the
   kind-specific closed forms of :mod:`._init` when the cam frames are solved too;
2. Levenberg-Marquardt on the frames (:func:`register`; calibration runs it as a logged
   stage, :class:`~kinecal.identification._stages.Register`).

Pose data are registered from their positions first, so a new session's orientations
never buy their fit with the positions, and the orientation residuals are then tested for
a common rotation (a turned probe). Every frame whose Euler pitch comes within 15 deg of
90 deg gets a reference rotation, so
no path works at gimbal lock; a set whose points do not fix its rotation (two targets,
or all on one line) gets the rotation nearest to its current one that fits them, and a
``rotation_undetermined`` diagnostic.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from kinecal._record import Record
from kinecal.errors import IdentifiabilityError
from kinecal.geometry import project_to_so3, rigid_fit_nearest, so3_log
from kinecal.identification._init import closed_form_frames, euler_with_reference
from kinecal.identification._lm import LMOptions, LMResult, NormalSource, solve_lm
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import Weights, residuals
from kinecal.models import CalibrationModel, ModelInputs
from kinecal.typing import Float

__all__ = ["FRAME_GROUPS", "Registration", "initial_registration", "register"]

FRAME_GROUPS = ("base", "cam")


def _user_frames(
    model: CalibrationModel, x: Float, meas: Measurements, inputs: ModelInputs
) -> tuple[CalibrationModel, Float, list[int]]:
    """User frames by Kabsch of the model's points in the base frame (the rest held)."""
    base_idx = model.base_index
    R_now, _ = model.base_frames(x)
    identity = np.broadcast_to(np.eye(3), model.R_ref_base.shape)
    probe = x.copy()
    probe[base_idx] = 0.0
    p_base = model.with_references(identity).evaluate(probe, inputs).p_user
    ref = meas.reference_points()
    out = x.copy()
    R_ref = model.R_ref_base.copy()
    loose = []
    for s, label in enumerate(model.spec.sets):
        rows = meas.set_index == s
        if rows.sum() < 3:
            raise IdentifiabilityError(
                f"{meas.source}: {_set_name(label)} has {_rows(int(rows.sum()))}; "
                "registering its user frame needs at least 3."
            )
        R, t, determined = rigid_fit_nearest(p_base[rows], ref[rows], R_now[s])
        R_ref[s], rwp = euler_with_reference(R)
        out[base_idx[s]] = np.concatenate([t, rwp])
        if not determined:
            loose.append(s)
    return model.with_references(R_ref), out, loose


def _undetermined(model: CalibrationModel, meas: Measurements, s: int) -> Diagnostic:
    """The diagnostic of a set whose data do not fix its user frame's rotation."""
    label = model.spec.sets[s]
    rows = meas.set_index == s
    names = tuple(model.layout.names[i] for i in model.base_index[s, 3:])
    return Diagnostic(
        "rotation_undetermined",
        f"set {label or '(default)'}: the points its {int(rows.sum())} rows measure lie "
        "on one line (or are one point), so the rotation of its user frame about that "
        "line is not determined; it is kept nearest its previous value. Measure at "
        "least three points (targets) not on one line.",
        parameters=names,
        rows=tuple(int(r) for r in meas.rows[rows][:20]),
        stage="registration",
    )


def initial_registration(
    model: CalibrationModel,
    x: Float,
    meas: Measurements,
    groups: Iterable[str] = FRAME_GROUPS,
    inputs: ModelInputs | None = None,
    flange: tuple[Float, Float] | None = None,
) -> tuple[CalibrationModel, Float, list[Diagnostic]]:
    """Closed-form frames of ``groups`` ('base': user frames, 'cam': cam frames) with
    the other parameters of ``x`` held (``flange``: its flange frames, if evaluated).

    Returns
    -------
    model : the model with reference rotations where a frame is near gimbal lock.
    x : (P,) the parameters with the frames set.
    diagnostics : ``rotation_undetermined`` for sets whose points do not fix it.
    """
    solve = set(groups) & set(FRAME_GROUPS)
    if not solve:
        return model, x.copy(), []
    if "cam" not in solve:
        inp = inputs if inputs is not None else meas.model_inputs()
        model, out, loose = _user_frames(model, x, meas, inp)
    else:
        joint, out, loose = closed_form_frames(model, x, meas, flange)
        if "base" in solve:
            model = joint
        else:  # cam frames alone: the joint closed form's cam part, user frames kept
            out[model.base_index] = x[model.base_index]
            R_cam = joint.R_ref_cam if model.spec.cam_rotation else None
            model, loose = model.with_references(None, R_cam), []
    return model, out, [_undetermined(model, meas, s) for s in loose]


@dataclass(frozen=True, eq=False, repr=False)
class Registration(Record):
    """Outcome of :func:`register`."""

    model: CalibrationModel
    x: Float
    result: LMResult
    diagnostics: tuple[Diagnostic, ...]


def register(
    model: CalibrationModel,
    x: Float,
    meas: Measurements,
    free: np.ndarray,
    *,
    groups: Iterable[str] = FRAME_GROUPS,
    weights: Weights | None = None,
    inputs: ModelInputs | None = None,
    max_iter: int = 100,
) -> Registration:
    """Closed-form start of the frames in ``groups``, then LM on the ``free`` parameters.

    Pose data are registered positions first (:func:`_register_pose`): a new session's
    orientations never buy their fit with the positions.

    Parameters
    ----------
    model, x : the model and its current parameters (held where not free).
    meas : the data to register.
    free : (P,) bool, the parameters the LM refines (usually the frames of ``groups``).
    """
    inp = inputs if inputs is not None else meas.model_inputs()
    if meas.kind == "pose":
        return _register_pose(model, x, meas, free, tuple(groups), inp, max_iter)
    model, x0, found = initial_registration(model, x, meas, groups, inp)
    w = weights if weights is not None else Weights.default(meas)
    res = _lm(model, x0, meas, free, w, inp, max_iter)
    return Registration(model, res.x, res, tuple(found))


def _lm(
    model: CalibrationModel,
    x0: Float,
    meas: Measurements,
    free: np.ndarray,
    w: Weights,
    inputs: ModelInputs,
    max_iter: int,
) -> LMResult:
    def fun(xx: Float, jac: bool) -> tuple[Float, Float | NormalSource | None]:
        blk = residuals(model, xx, meas, w, inputs=inputs, jacobian=jac)
        return blk.r, blk.jacobian  # held, or by blocks for large data

    return solve_lm(
        fun,
        x0,
        free,
        model.layout.scales,
        LMOptions(max_iter=max_iter),
        label="registration",
    )


def _positions(meas: Measurements) -> Measurements:
    """The positions of pose data, as point data."""
    return replace(meas, kind="point", R_user_cam=None, sigma_rot=None)


def _rms_pos(
    model: CalibrationModel, x: Float, meas: Measurements, inp: ModelInputs
) -> float:
    e = residuals(model, x, meas, Weights.default(meas), inputs=inp).raw_position
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def _register_pose(
    model: CalibrationModel,
    x: Float,
    meas: Measurements,
    free: np.ndarray,
    groups: tuple[str, ...],
    inp: ModelInputs,
    max_iter: int,
) -> Registration:
    """Pose data: the frames from the positions first (the tool's rotation held), the
    tool's rotation from the orientations in closed form (when it is refitted), then the
    orientations too, weighed by this session's own scatter, kept only where the
    positions fit as well (within 2 %). Then a test of the orientation residuals for a
    common rotation (``orientation_offset``: a turned probe)."""
    pts = _positions(meas)
    model, x0, found = initial_registration(model, x, pts, groups, inp)
    cam_rot = np.zeros(model.size, bool)
    cam_rot[model.layout.select(group="cam", field=("r", "w", "p"))] = True
    res_p = _lm(model, x0, pts, free & ~cam_rot, Weights.default(pts), inp, max_iter)
    x1 = res_p.x
    if "cam" in groups and model.spec.cam_rotation and np.any(free & cam_rot):
        model, x1 = _tool_rotation(model, x1, meas, inp)
    blk = residuals(model, x1, meas, Weights.default(meas), inputs=inp)
    assert blk.raw_rotation is not None
    w = (
        Weights.default(meas)
        if meas.sigma is not None and meas.sigma_rot is not None
        else Weights(
            np.full(meas.n, max(float(np.sqrt(np.mean(blk.raw_position**2))), 1e-9)),
            np.full(meas.n, max(float(np.sqrt(np.mean(blk.raw_rotation**2))), 1e-9)),
        )
    )
    res = _lm(model, x1, meas, free, w, inp, max_iter)
    keep_pose = _rms_pos(model, res.x, pts, inp) <= 1.02 * _rms_pos(model, x1, pts, inp)
    x_out = res.x if keep_pose else x1
    found += _orientation_offset(model, x_out, meas, inp, bool(np.any(free & cam_rot)))
    return Registration(model, x_out, res if keep_pose else res_p, tuple(found))


def _rotation_errors(
    model: CalibrationModel, x: Float, meas: Measurements, inp: ModelInputs
) -> Float:
    """``R_model^T R_meas`` of every row (N, 3, 3): the measured orientation in the
    model's tool frame."""
    out = model.evaluate(x, inp, orientation=True)
    assert out.R_user_cam is not None and meas.R_user_cam is not None
    return np.swapaxes(out.R_user_cam, 1, 2) @ meas.R_user_cam


def _tool_rotation(
    model: CalibrationModel, x: Float, meas: Measurements, inp: ModelInputs
) -> tuple[CalibrationModel, Float]:
    """Each marker's tool rotation turned by the mean rotation between the model's and
    the measured orientations (closed form, in the tool frame)."""
    delta = _rotation_errors(model, x, meas, inp)
    R_cam, _ = model.cam_frames(x)
    R_ref = model.R_ref_cam.copy()
    out = x.copy()
    for m in range(len(model.spec.markers)):
        rows = meas.marker_index == m
        if not rows.any():
            continue
        turn = project_to_so3(delta[rows].mean(axis=0))
        R_ref[m], rwp = euler_with_reference(R_cam[m] @ turn)
        out[model.cam_index[m, 3:]] = rwp
    return model.with_references(None, R_ref), out


def _orientation_offset(
    model: CalibrationModel,
    x: Float,
    meas: Measurements,
    inp: ModelInputs,
    tool_refitted: bool,
) -> list[Diagnostic]:
    """``orientation_offset`` when the orientation residuals share a rotation well above
    their scatter (their mean beyond the scatter itself and beyond 3 standard errors)."""
    delta = _rotation_errors(model, x, meas, inp)  # (N, 3, 3) in the tool frame
    common = project_to_so3(delta.mean(axis=0))  # chordal mean: fine near 180 deg too
    mean = so3_log(common)
    spread = so3_log(np.swapaxes(common, 0, 1)[None] @ delta)  # about the mean
    scatter = float(np.sqrt(np.mean(np.sum(spread**2, axis=1))))
    size = float(np.linalg.norm(mean))
    if size <= max(scatter, 3.0 * scatter / np.sqrt(meas.n), 1e-9):
        return []
    axis = mean / size
    hint = (
        " The tool was refitted: the markers may have moved against each other."
        if tool_refitted
        else " Was the tool (probe, reflector nest) re-mounted or turned? "
        "--refit user,tool re-estimates it."
    )
    return [
        Diagnostic(
            "orientation_offset",
            f"the measured orientations differ from the model's by a common rotation "
            f"of {np.degrees(size):.3g} deg about ({axis[0]:.3f}, {axis[1]:.3f}, "
            f"{axis[2]:.3f}) in the tool frame, far above their scatter "
            f"({np.degrees(scatter):.2g} deg).{hint}",
            rows=tuple(int(r) for r in meas.rows[:20]),
            stage="registration",
        )
    ]


def _set_name(label: str) -> str:
    """``set 'A'``, or the default set (data without a set column) in words."""
    return f"set {label!r}" if label else "the data (one set)"


def _rows(n: int) -> str:
    return f"{n} row{'s' if n != 1 else ''}"
