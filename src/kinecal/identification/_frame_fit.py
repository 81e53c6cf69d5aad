"""Registration's fit of the user and cam frames without passes of the model (issue 36).

With every other parameter held, the model's point is ``R_b (o + R_f (t_c + R_c p_cam))
+ t_b`` (user frame ``R_b, t_b`` of the row's set, cam frame ``R_c, t_c`` of its marker,
flange frame ``R_f, o`` in the model base) and its orientation ``R_b R_f R_c``. The
flange frames take one forward pass; the predictions and the frames' Jacobian columns
(:meth:`ModelDefinition.base_axes`, ``cam_axes``: the angular velocities of the Euler
angles) follow from them for any frames, to rounding the model's own numbers.

This holds where no deflection depends on the frames: every joint compliance zero, as
at the nominal start (the tool's position moves the payload's torque otherwise).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal._record import Record, ReprRecord
from kinecal.geometry import so3_right_jacobian_inv
from kinecal.measurement import _blocks
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import Weights, whiten
from kinecal.models import CalibrationModel, ModelInputs, ModelOutput
from kinecal.typing import Float

__all__ = ["FrameBlock", "FrameFit"]


@dataclass(frozen=True, eq=False, repr=False)
class FrameFit(ReprRecord):
    """Residual blocks of one model's data with only its frames moving, from the flange
    frames at ``x``: what :class:`~kinecal.identification._problem.EvaluationCache`
    gives, with the normal equations of the frames' columns alone (no other column
    is asked for in a fit of the frames)."""

    model: CalibrationModel
    meas: Measurements
    inputs: ModelInputs
    flange: tuple[Float, Float]  # (R (N, 3, 3), o (N, 3)) in the model base

    @classmethod
    def of(
        cls,
        model: CalibrationModel,
        x: Float,
        meas: Measurements,
        inputs: ModelInputs,
    ) -> FrameFit | None:
        """The fit of ``model``'s frames from ``x`` (one forward pass); None where a
        compliance term is not zero or the data are evaluated by blocks."""
        kinds = np.array([s.kind for s in model.layout.specs])
        if np.any(x[kinds == "compliance"] != 0.0):
            return None
        if meas.n * meas.components > _blocks.BLOCK_ROWS:
            return None
        # The model's tool pose with the user frames at the identity, less the cam
        # frame: the flange (the compiled kernel's forward pass where it is built).
        bare = model.with_references(np.broadcast_to(np.eye(3), model.R_ref_base.shape))
        x0 = x.copy()
        x0[bare.base_index] = 0.0
        out = bare.evaluate(x0, inputs, orientation=True)
        assert out.R_user_cam is not None
        R_c, t_c = bare.cam_frames(x0)
        mi = inputs.marker_index
        R_fl = out.R_user_cam @ np.swapaxes(R_c, 1, 2)[mi]
        o_fl = out.p_user - np.einsum(
            "nij,nj->ni", R_fl, t_c[mi] + np.einsum("nij,nj->ni", R_c[mi], inputs.p_cam)
        )
        return cls(model, meas, inputs, (R_fl, o_fl))

    def on(self, model: CalibrationModel) -> FrameFit:
        """The same fit of ``model`` (the same kinematics, other reference rotations:
        the closed form's)."""
        return replace(self, model=model)

    def __call__(
        self,
        cm: CalibrationModel,
        x: Float,
        w: Weights,
        *,
        jacobian: bool = False,
        products: bool = False,
    ) -> FrameBlock:
        """The residual block at ``x`` (its frames moved from the flange frames')."""
        assert cm is self.model and not products
        meas, pose = self.meas, self.meas.kind == "pose"
        p, R_uc, parts = self._predict(x, jacobian, pose)
        out = ModelOutput(p, R_uc, None, None, self.inputs.q_ctrl)
        ref = meas.reference_points()
        r, _, e_p, e_r = whiten(out, ref, meas.R_user_cam, w.sigma, w.sigma_rot, False)
        if parts is None:
            return FrameBlock(r, e_p, e_r, None)
        si, mi = self.inputs.set_index, self.inputs.marker_index
        N, c = r.shape
        cols = np.concatenate([cm.base_index.ravel(), cm.cam_index.ravel()])
        J = np.zeros((N, c, cols.size))  # the frames' columns alone
        rot = None
        if e_r is not None and w.sigma_rot is not None:
            rot = so3_right_jacobian_inv(-e_r) * (1.0 / w.sigma_rot)[:, None, None]
        # Each row's columns of its own user frame, then of its own cam frame.
        at = 0
        for J_p, J_w, index, of in (
            (*parts[:2], cm.base_index, si),
            (*parts[2:], cm.cam_index, mi),
        ):
            J_p *= (1.0 / w.sigma)[:, None, None]  # whitened as the model's
            J_r = None if rot is None else rot @ J_w
            n = index.shape[1]
            for k in range(len(index)):
                mine = None if len(index) == 1 else (of == k)[:, None, None]
                J[:, :3, at : at + n] = J_p if mine is None else J_p * mine
                if J_r is not None:
                    J[:, 3:, at : at + n] = J_r if mine is None else J_r * mine
                at += n
        return FrameBlock(r, e_p, e_r, _FrameNormal(r, J, cols, cm.size))

    def rms_mm(self, cm: CalibrationModel, x: Float, w: Weights) -> float:
        """RMS of the 3-D position errors at ``x`` [mm]."""
        e_p = self(cm, x, w).raw_position
        return float(np.sqrt(np.mean(np.sum(e_p**2, axis=1)))) * 1e3

    def _predict(
        self, x: Float, jacobian: bool, orientation: bool
    ) -> tuple[Float, Float | None, tuple[Float, Float, Float, Float] | None]:
        """The model's point and orientation at ``x`` and, with ``jacobian``, the
        columns of each row's own user frame (``d p_user`` and the angular velocity,
        (N, 3, 6) each), then of its own cam frame."""
        cm, inp = self.model, self.inputs
        R_fl, o_fl = self.flange
        si, mi = inp.set_index, inp.marker_index
        R_b, t_b = cm.base_frames(x)
        R_c, t_c = cm.cam_frames(x)
        Rb, Rc = _per_row(R_b, si), _per_row(R_c, mi)  # (3, 3) for one set or marker
        v = _apply(Rc, inp.p_cam)  # the point in the flange
        p = _apply(Rb, o_fl + _apply(R_fl, _per_row(t_c, mi) + v)) + _per_row(t_b, si)
        R_bf = Rb @ R_fl if orientation or jacobian else None
        R_uc = R_bf @ Rc if R_bf is not None and orientation else None
        if R_bf is None:
            return p, R_uc, None
        N, nc = p.shape[0], cm.cam_index.shape[1]
        # Each row's columns of its own user frame (6) and cam frame (nc).
        Jb, Jwb = np.zeros((N, 3, 6)), np.zeros((N, 3, 6))
        Jb[:, :, :3] = np.eye(3)
        axes = _per_row(cm.definition.base_axes(x), si)  # the Euler angles' axes
        Jb[:, :, 3:] = _cross_columns(axes, p - _per_row(t_b, si))
        Jwb[:, :, 3:] = axes
        Jc, Jwc = np.zeros((N, 3, nc)), np.zeros((N, 3, nc))
        Jc[:, :, :3] = R_bf
        if nc == 6:
            cam_axes = R_bf @ _per_row(cm.definition.cam_axes(x), mi)  # user frame
            Jc[:, :, 3:] = _cross_columns(cam_axes, _apply(R_bf, v))
            Jwc[:, :, 3:] = cam_axes
        return p, R_uc, (Jb, Jwb, Jc, Jwc)


def _cross_columns(A: Float, b: Float) -> Float:
    """``A[..., :, k] x b`` for every column k of A ((3, 3) or (N, 3, 3)), b (N, 3):
    (N, 3, 3)."""
    a0, a1, a2 = A[..., 0, :], A[..., 1, :], A[..., 2, :]
    b0, b1, b2 = b[:, 0, None], b[:, 1, None], b[:, 2, None]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=1)


def _per_row(frames: Float, index: np.ndarray) -> Float:
    """The frame of each row, ``frames[index]``; the frame itself (no copy per row)
    where there is one."""
    return frames[0] if frames.shape[0] == 1 else frames[index]


def _apply(R: Float, v: Float) -> Float:
    """``R v`` row by row, R (3, 3) or (N, 3, 3), v (N, 3)."""
    return v @ R.T if R.ndim == 2 else np.einsum("nij,nj->ni", R, v)


@dataclass(frozen=True, eq=False, repr=False)
class _FrameNormal(Record):
    """The normal equations of the frames' Jacobian columns (N, c, K) at ``cols`` of
    the model's P parameters (:class:`~kinecal.identification._normal.NormalSource`)."""

    r: Float
    J: Float
    cols: np.ndarray
    size: int

    def normal(
        self, cols: np.ndarray, scales: Float, row_weights: Float | None = None
    ) -> tuple[Float, Float]:
        where = np.full(self.size, -1)
        where[self.cols] = np.arange(self.cols.size)
        sel = where[np.asarray(cols, dtype=np.intp)]
        if np.any(sel < 0):
            raise ValueError(
                "a fit of the frames asked for another parameter's column."
            )
        X, r = self.J[:, :, sel] * scales, self.r
        if row_weights is not None:
            X, r = X * row_weights[:, None, None], r * row_weights[:, None]
        Xm = X.reshape(-1, sel.size)
        return Xm.T @ Xm, Xm.T @ r.reshape(-1)


@dataclass(frozen=True, eq=False, repr=False)
class FrameBlock(Record):
    """A :class:`~kinecal.measurement._residuals.ResidualBlock` of a fit of the frames:
    whitened residuals, raw errors, and the normal equations of the frames' columns
    (``jacobian``, when asked for)."""

    r: Float
    raw_position: Float
    raw_rotation: Float | None
    jacobian: _FrameNormal | None
