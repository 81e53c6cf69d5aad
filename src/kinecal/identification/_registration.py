"""Registration: the user and tool frames of a data set, the rest of the model held.

One path serves calibration (every frame, from nominal kinematics), refit on a new
session (``--refit user``: the user frames; ``tool``: the cam frames) and the held-out
sets of cross-validation:

1. a closed-form start (:func:`initial_registration`): Kabsch/Umeyama of the model's
   points in the robot base frame onto the measurements for the user frames alone, the
   kind-specific closed forms of :mod:`._init` when the cam frames are solved too;
2. Levenberg-Marquardt on the frames (:func:`register`; calibration runs it as a logged
   stage, :class:`~kinecal.identification._stages.Register`).

Every frame whose Euler pitch comes within 15 deg of 90 deg gets a reference rotation, so
no path works at gimbal lock; a set whose points do not fix its rotation (two targets,
or all on one line) gets the rotation nearest to its current one that fits them, and a
``rotation_undetermined`` diagnostic.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from kinecal.errors import IdentifiabilityError
from kinecal.geometry import rigid_fit_nearest
from kinecal.identification._diagnostics import Diagnostic
from kinecal.identification._init import closed_form_frames, euler_with_reference
from kinecal.identification._lm import LMOptions, LMResult, solve_lm
from kinecal.identification._measurements import Measurements
from kinecal.identification._residuals import Weights, residuals
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
                f"{meas.source}: set {label!r} has {rows.sum()} rows; registering its "
                "user frame needs at least 3."
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
) -> tuple[CalibrationModel, Float, list[Diagnostic]]:
    """Closed-form frames of ``groups`` ('base': user frames, 'cam': cam frames) with
    the other parameters of ``x`` held.

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
        joint, out, loose = closed_form_frames(model, x, meas)
        if "base" in solve:
            model = joint
        else:  # cam frames alone: the joint closed form's cam part, user frames kept
            out[model.base_index] = x[model.base_index]
            R_cam = joint.R_ref_cam if model.spec.cam_rotation else None
            model, loose = model.with_references(None, R_cam), []
    return model, out, [_undetermined(model, meas, s) for s in loose]


@dataclass(frozen=True)
class Registration:
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

    Parameters
    ----------
    model, x : the model and its current parameters (held where not free).
    meas : the data to register.
    free : (P,) bool, the parameters the LM refines (usually the frames of ``groups``).
    """
    inp = inputs if inputs is not None else meas.model_inputs()
    model, x0, found = initial_registration(model, x, meas, groups, inp)
    w = weights if weights is not None else Weights.default(meas)

    def fun(xx: Float, jac: bool) -> tuple[Float, Float | None]:
        blk = residuals(model, xx, meas, w, inputs=inp, jacobian=jac)
        return blk.r, blk.J

    res = solve_lm(
        fun,
        x0,
        free,
        model.layout.scales,
        LMOptions(max_iter=max_iter),
        label="registration",
    )
    return Registration(model, res.x, res, tuple(found))
