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

from dataclasses import dataclass

import numpy as np

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
    R_fl: Float  # (N, 3, 3) flange frames in the model base
    o_fl: Float  # (N, 3)

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
        R_fl, o_fl = model.flange_frames(x, inputs)
        return cls(model, meas, inputs, R_fl, o_fl)

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
        meas = self.meas
        out = self.output(x, jacobian, meas.kind == "pose")
        r, J, e_p, e_r = whiten(
            out,
            meas.reference_points(),
            meas.R_user_cam,
            w.sigma,
            w.sigma_rot,
            jacobian,
        )
        return ResidualBlock(r, J, e_p, e_r)

    def rms_mm(self, cm: CalibrationModel, x: Float, w: Weights) -> float:
        """RMS of the 3-D position errors at ``x`` [mm]."""
        e_p = self(cm, x, w).raw_position
        return float(np.sqrt(np.mean(np.sum(e_p**2, axis=1)))) * 1e3

    def output(self, x: Float, jacobian: bool, orientation: bool) -> ModelOutput:
        """The model's output at ``x`` (its Jacobian: the frames' columns)."""
        cm, inp = self.model, self.inputs
        si, mi = inp.set_index, inp.marker_index
        R_b, t_b = cm.base_frames(x)
        R_c, t_c = cm.cam_frames(x)
        R_bf = R_b[si] @ self.R_fl
        v = np.einsum("nij,nj->ni", R_c[mi], inp.p_cam)  # the point in the flange
        y = self.o_fl + np.einsum("nij,nj->ni", self.R_fl, t_c[mi] + v)
        p = np.einsum("nij,nj->ni", R_b[si], y) + t_b[si]
        R_uc = R_bf @ R_c[mi] if orientation else None
        if not jacobian:
            return ModelOutput(p, R_uc, None, None, inp.q_ctrl)
        N, P = p.shape[0], cm.size
        # The model's layout: parameter-major, (N, 3, P) views.
        J_p = np.zeros((P, 3, N)).transpose(2, 1, 0)
        J_w = np.zeros((P, 3, N)).transpose(2, 1, 0)
        bi, ci = cm.base_index, cm.cam_index
        axes = cm.definition.base_axes(x)  # (S, 3, 3): the Euler angles' axes
        arm = p - t_b[si]
        for s in range(bi.shape[0]):
            rows = np.flatnonzero(si == s)
            for k in range(3):
                J_p[rows, k, bi[s, k]] = 1.0
                J_p[rows, :, bi[s, 3 + k]] = np.cross(axes[s, :, k], arm[rows])
                J_w[rows, :, bi[s, 3 + k]] = axes[s, :, k]
        cam_axes = cm.definition.cam_axes(x) if ci.shape[1] == 6 else None
        for m in range(ci.shape[0]):
            rows = np.flatnonzero(mi == m)
            for k in range(3):
                J_p[rows, :, ci[m, k]] = R_bf[rows, :, k]
                if cam_axes is None:
                    continue
                a = cam_axes[m, :, k]
                J_p[rows, :, ci[m, 3 + k]] = np.einsum(
                    "nij,nj->ni", R_bf[rows], np.cross(a, v[rows])
                )
                J_w[rows, :, ci[m, 3 + k]] = R_bf[rows] @ a
        return ModelOutput(p, R_uc, J_p, J_w if orientation else None, inp.q_ctrl)
