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

from kinecal.geometry import so3_right_jacobian_inv
from kinecal.measurement import _blocks
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import ResidualBlock, Weights, whiten
from kinecal.models import CalibrationModel, ModelInputs, ModelOutput
from kinecal.typing import Float

__all__ = ["FrameFit"]


@dataclass(frozen=True, eq=False)
class FrameFit:
    """Residual blocks of one model's data with only its frames moving, from the flange
    frames at ``x`` (what :class:`~kinecal.identification._problem.EvaluationCache`
    gives for the frames' columns; the other columns of its Jacobians are zero)."""

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
    ) -> ResidualBlock:
        """The residual block at ``x`` (its frames moved from the flange frames')."""
        assert cm is self.model and not products
        meas, pose = self.meas, self.meas.kind == "pose"
        p, R_uc, parts = self._predict(x, jacobian, pose)
        out = ModelOutput(p, R_uc, None, None, self.inputs.q_ctrl)
        ref = meas.reference_points()
        r, _, e_p, e_r = whiten(out, ref, meas.R_user_cam, w.sigma, w.sigma_rot, False)
        if parts is None:
            return ResidualBlock(r, None, e_p, e_r)
        si, mi = self.inputs.set_index, self.inputs.marker_index
        N, c = r.shape
        J = np.zeros((cm.size, c, N)).transpose(2, 1, 0)  # the model's layout
        rot = None
        if e_r is not None and w.sigma_rot is not None:
            rot = so3_right_jacobian_inv(-e_r) * (1.0 / w.sigma_rot)[:, None, None]
        # Each row's columns of its own user frame, then of its own cam frame.
        for (J_p, J_w), index, of in (
            (parts[:2], cm.base_index, si),
            (parts[2:], cm.cam_index, mi),
        ):
            J_p *= (1.0 / w.sigma)[:, None, None]  # whitened as the model's
            J_r = None if rot is None else rot @ J_w
            for k, cols in enumerate(index):
                mine = None if len(index) == 1 else (of == k)[:, None, None]
                J[:, :3, cols] = J_p if mine is None else J_p * mine
                if J_r is not None:
                    J[:, 3:, cols] = J_r if mine is None else J_r * mine
        return ResidualBlock(r, J, e_p, e_r)

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
        R_bf = R_b[si] @ R_fl
        v = np.einsum("nij,nj->ni", R_c[mi], inp.p_cam)  # the point in the flange
        y = o_fl + np.einsum("nij,nj->ni", R_fl, t_c[mi] + v)
        p = np.einsum("nij,nj->ni", R_b[si], y) + t_b[si]
        R_uc = R_bf @ R_c[mi] if orientation else None
        if not jacobian:
            return p, R_uc, None
        N, nc = p.shape[0], cm.cam_index.shape[1]
        # Each row's columns of its own user frame (6) and cam frame (nc).
        Jb, Jwb = np.zeros((N, 3, 6)), np.zeros((N, 3, 6))
        Jb[:, :, :3] = np.eye(3)
        axes = cm.definition.base_axes(x)[si]  # (N, 3, 3): the Euler angles' axes
        Jb[:, :, 3:] = _cross_columns(axes, p - t_b[si])
        Jwb[:, :, 3:] = axes
        Jc, Jwc = np.zeros((N, 3, nc)), np.zeros((N, 3, nc))
        Jc[:, :, :3] = R_bf
        if nc == 6:
            cam_axes = R_bf @ cm.definition.cam_axes(x)[mi]  # in the user frame
            Jc[:, :, 3:] = _cross_columns(cam_axes, np.einsum("nij,nj->ni", R_bf, v))
            Jwc[:, :, 3:] = cam_axes
        return p, R_uc, (Jb, Jwb, Jc, Jwc)


def _cross_columns(A: Float, b: Float) -> Float:
    """``A[:, :, k] x b`` for every column k of A (N, 3, 3), b (N, 3): (N, 3, 3)."""
    return np.swapaxes(np.cross(np.swapaxes(A, 1, 2), b[:, None, :]), 1, 2)
