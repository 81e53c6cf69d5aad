"""Residuals and their Jacobians for each measurement kind (DESIGN §7).

Residuals are model minus reference, in the user frame, sample-major then component:

* point, sensor: ``r_i = p_model_i - p_ref_i`` (3 per row; for sensor data
  ``p_model = T_user_cam(q) p_cam``, Eq. 6);
* pose: ``[p_model - p_meas, log(R_model R_meas^T)]`` (6 per row; the rotation part is
  the rotation vector of the orientation error in the user frame).

Rows are whitened by their standard deviations: ``r / sigma``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.geometry import so3_log, so3_right_jacobian_inv
from kinecal.identification._measurements import Measurements
from kinecal.models import CalibrationModel, ForwardState, ModelInputs
from kinecal.typing import Float

__all__ = ["ResidualBlock", "Weights", "errors_mm", "residuals"]


@dataclass(frozen=True)
class Weights:
    """Standard deviations used to whiten the residuals.

    Attributes
    ----------
    sigma : (N,) position sigma per row [m].
    sigma_rot : (N,) or None, rotation sigma per row [rad] (pose data).
    """

    sigma: Float
    sigma_rot: Float | None = None

    @classmethod
    def default(
        cls, meas: Measurements, sigma_m: float = 1e-4, sigma_rot: float = 1e-3
    ) -> Weights:
        """Per-row sigmas from the data, or defaults (0.1 mm, 1 mrad) where absent."""
        s = meas.sigma if meas.sigma is not None else np.full(meas.n, sigma_m)
        sr = None
        if meas.kind == "pose":
            sr = (
                meas.sigma_rot
                if meas.sigma_rot is not None
                else np.full(meas.n, sigma_rot)
            )
        return cls(np.asarray(s, float), None if sr is None else np.asarray(sr, float))

    def subset(self, rows: np.ndarray) -> Weights:
        return Weights(
            self.sigma[rows], None if self.sigma_rot is None else self.sigma_rot[rows]
        )


@dataclass(frozen=True)
class ResidualBlock:
    """Whitened residuals ``r`` (N, c) and Jacobian ``J`` (N, c, P) of one evaluation."""

    r: Float
    J: Float | None
    raw_position: Float  # (N, 3) unwhitened position error, model - reference [m]
    raw_rotation: Float | None  # (N, 3) unwhitened rotation error [rad]
    forward: ForwardState | None = None  # the model's state, with ``keep``


def residuals(
    model: CalibrationModel,
    params: Float,
    meas: Measurements,
    weights: Weights,
    *,
    inputs: ModelInputs | None = None,
    jacobian: bool = False,
    products: bool = False,
    keep: bool = False,
    reuse: ForwardState | None = None,
) -> ResidualBlock:
    """Evaluate the whitened residuals (and Jacobian) of ``meas`` under ``model``.

    Parameters
    ----------
    model : CalibrationModel
    params : (P,) parameter vector
    meas : Measurements
    weights : Weights
    inputs : ModelInputs, optional
        Precomputed ``meas.model_inputs()`` (saves work in loops).
    jacobian : bool
    products : bool
        With ``jacobian``, also the columns of the link products
        (:meth:`CalibrationModel.evaluate`).
    keep, reuse :
        Keep the model's forward state in the block, or reuse one kept at the same point
        (:meth:`CalibrationModel.evaluate`): a Jacobian after a plain evaluation at the
        same parameters then skips the forward kinematics.
    """
    inp = inputs if inputs is not None else meas.model_inputs()
    pose = meas.kind == "pose"
    out = model.evaluate(
        params,
        inp,
        orientation=pose,
        jacobian=jacobian,
        products=products,
        keep=keep,
        reuse=reuse,
    )
    e_p = out.p_user - meas.reference_points()  # model minus measurement; Eq. (6)
    inv_s = 1.0 / weights.sigma
    if not pose:
        r = e_p * inv_s[:, None]
        J = out.J_p
        if J is not None:
            J *= inv_s[:, None, None]  # the model's fresh array: whitened in place
        return ResidualBlock(r, J, e_p, None, out.forward)
    assert out.R_user_cam is not None and meas.R_user_cam is not None
    assert weights.sigma_rot is not None
    e_r = so3_log(
        out.R_user_cam @ np.swapaxes(meas.R_user_cam, 1, 2)
    )  # log(R R_meas^T)
    inv_sr = 1.0 / weights.sigma_rot
    r = np.concatenate([e_p * inv_s[:, None], e_r * inv_sr[:, None]], axis=1)
    J = None
    if jacobian:
        assert out.J_p is not None and out.J_w is not None
        # R_model -> exp(J_w dx) R_model gives log(exp(w) exp(e_r)) ~ e_r + J_l^-1(e_r) w,
        # and J_l^-1(e_r) = J_r^-1(-e_r).
        J_l_inv = so3_right_jacobian_inv(-e_r)
        # Both parts into one parameter-major array, the model's layout.
        N, _, P = out.J_p.shape
        J = np.empty((P, 6, N)).transpose(2, 1, 0)
        np.multiply(out.J_p, inv_s[:, None, None], out=J[:, :3])
        np.matmul(J_l_inv, out.J_w, out=J[:, 3:])
        J[:, 3:] *= inv_sr[:, None, None]
    return ResidualBlock(r, J, e_p, e_r, out.forward)


def errors_mm(block: ResidualBlock) -> Float:
    """3-D position error norm of every row [mm]."""
    return np.linalg.norm(block.raw_position, axis=1) * 1e3
