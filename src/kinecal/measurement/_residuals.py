"""Residuals and their Jacobians for each measurement kind (DESIGN §7).

Residuals are model minus reference, in the user frame, sample-major then component:

* point, sensor: ``r_i = p_model_i - p_ref_i`` (3 per row; for sensor data
  ``p_model = T_user_cam(q) p_cam``, Eq. 6);
* pose: ``[p_model - p_meas, log(R_model R_meas^T)]`` (6 per row; the rotation part is
  the rotation vector of the orientation error in the user frame).

Rows are whitened by their standard deviations: ``r / sigma``.

A Jacobian of more than :data:`BLOCK_ROWS` residual rows is not held whole (a million
poses of the full model would take 1.3 GB): the block carries a
:class:`~kinecal.measurement._blocks.BlockJacobian` that evaluates it by blocks of
poses whenever a product is needed (``normal``), with the same numbers to rounding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from kinecal._record import Record
from kinecal.geometry import so3_log, so3_right_jacobian_inv
from kinecal.measurement import _blocks
from kinecal.measurement._blocks import BlockJacobian
from kinecal.measurement._measurements import Measurements
from kinecal.models import CalibrationModel, ModelInputs, ModelOutput
from kinecal.typing import Float

if TYPE_CHECKING:  # loaded by the numpy code only (not by the compiled kernel's)
    from kinecal.models import ForwardState

__all__ = ["ResidualBlock", "Weights", "errors_mm", "residuals"]


@dataclass(frozen=True, eq=False, repr=False)
class Weights(Record):
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

    def subset(self, rows: np.ndarray | slice) -> Weights:
        return Weights(
            self.sigma[rows], None if self.sigma_rot is None else self.sigma_rot[rows]
        )


@dataclass(frozen=True, eq=False, repr=False)
class ResidualBlock(Record):
    """Whitened residuals ``r`` (N, c) and Jacobian ``J`` (N, c, P) of one evaluation.

    ``J`` is None when not asked for, and for large data (``blocks``, then, gives its
    products: :meth:`normal`, :meth:`jacobian_blocks`).
    """

    r: Float
    J: Float | None
    raw_position: Float  # (N, 3) unwhitened position error, model - reference [m]
    raw_rotation: Float | None  # (N, 3) unwhitened rotation error [rad]
    forward: ForwardState | None = None  # the model's state, with ``keep``
    blocks: BlockJacobian | None = None  # the Jacobian by blocks (large data)

    def has_jacobian(self, n_cols: int) -> bool:
        """Whether the block gives Jacobians of ``n_cols`` columns (held or by blocks)."""
        return self.blocks is not None or (
            self.J is not None and self.J.shape[-1] >= n_cols
        )

    @property
    def jacobian(self) -> Float | BlockJacobian | None:
        """``J`` where it is held, else the block-wise Jacobian (None: not asked)."""
        return self.J if self.J is not None else self.blocks

    def normal(
        self, cols: np.ndarray, scales: Float, row_weights: Float | None = None
    ) -> tuple[Float, Float]:
        """``(Jsᵀ Js, Jsᵀ r)`` of the columns ``cols`` in scaled units
        (as :func:`~kinecal.identification.normal_equations`), held or by blocks."""
        if self.J is not None:
            cols = np.asarray(cols, dtype=np.intp)
            if cols.size == 0:
                return np.zeros((0, 0)), np.zeros(0)
            lo, hi = int(cols.min()), int(cols.max()) + 1
            A, g = _blocks.span_product(self.J, self.r, slice(lo, hi), row_weights)
            sel = cols - lo
            return A[np.ix_(sel, sel)] * np.outer(scales, scales), g[sel] * scales
        if self.blocks is None:
            raise ValueError("this residual block was evaluated without a Jacobian.")
        return self.blocks.normal(cols, scales, row_weights)

    def jacobian_blocks(self, rows: int = 20000) -> _blocks.Blocks:
        """``(rows slice, J rows (n, c, P'))`` over the data: slices of the held
        Jacobian (``rows`` at a time), or the blocks evaluated one after the other."""
        if self.J is not None:
            J, N = self.J, self.r.shape[0]
            return (
                (slice(lo, lo + rows), J[lo : lo + rows]) for lo in range(0, N, rows)
            )
        if self.blocks is None:
            raise ValueError("this residual block was evaluated without a Jacobian.")
        return self.blocks.blocks(products=False)


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
    hold: bool = False,
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
    hold : bool
        Hold the Jacobian whole whatever the size of the data.

    Notes
    -----
    Data of more than :data:`~kinecal.measurement._blocks.BLOCK_ROWS` residual rows
    are evaluated by blocks of poses: ``J`` is then None whatever ``jacobian`` says, and
    ``blocks`` evaluates the Jacobian's products on demand; nothing is kept (``keep``).
    """
    inp = inputs if inputs is not None else meas.model_inputs()
    params = np.asarray(params, np.float64)
    if not hold and meas.n * meas.components > _blocks.BLOCK_ROWS:
        return _by_blocks(model, params, meas, weights, inp)
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
    r, J, e_p, e_r = whiten(
        out,
        meas.reference_points(),
        meas.R_user_cam,
        weights.sigma,
        weights.sigma_rot,
        jacobian,
    )
    return ResidualBlock(r, J, e_p, e_r, out.forward)


def whiten(
    out: ModelOutput,
    p_ref: Float,
    R_meas: Float | None,
    sigma: Float,
    sigma_rot: Float | None,
    jacobian: bool,
    *,
    whiten_jacobian: bool = True,
) -> tuple[Float, Float | None, Float, Float | None]:
    """Whitened residuals ``r`` (N, c), Jacobian (N, c, P') or None, and the raw
    position (N, 3) and rotation errors of a model output (:class:`ModelOutput`) against
    the reference points ``p_ref`` (N, 3) and orientations ``R_meas`` (pose data).
    ``whiten_jacobian=False`` leaves a position-only Jacobian as the model gave it."""
    e_p = out.p_user - p_ref  # model minus measurement; Eq. (6)
    inv_s = 1.0 / sigma
    J_p = out.J_p
    if R_meas is None:
        r = e_p * inv_s[:, None]
        if J_p is not None and whiten_jacobian:
            J_p *= inv_s[:, None, None]  # the model's fresh array: whitened in place
        return r, J_p, e_p, None
    R_uc = out.R_user_cam
    assert R_uc is not None and sigma_rot is not None
    e_r = so3_log(R_uc @ np.swapaxes(R_meas, 1, 2))  # log(R R_meas^T)
    inv_sr = 1.0 / sigma_rot
    r = np.concatenate([e_p * inv_s[:, None], e_r * inv_sr[:, None]], axis=1)
    J = None
    if jacobian:
        J_w = out.J_w
        assert J_p is not None and J_w is not None
        # R_model -> exp(J_w dx) R_model gives log(exp(w) exp(e_r)) ~ e_r + J_l^-1(e_r) w,
        # and J_l^-1(e_r) = J_r^-1(-e_r).
        J_l_inv = so3_right_jacobian_inv(-e_r)
        # Both parts into one parameter-major array, the model's layout.
        N, _, P = J_p.shape
        J = np.empty((P, 6, N)).transpose(2, 1, 0)
        np.multiply(J_p, inv_s[:, None, None], out=J[:, :3])
        np.matmul(J_l_inv, J_w, out=J[:, 3:])
        J[:, 3:] *= inv_sr[:, None, None]
    return r, J, e_p, e_r


def _by_blocks(
    model: CalibrationModel,
    params: Float,
    meas: Measurements,
    weights: Weights,
    inputs: ModelInputs,
) -> ResidualBlock:
    """The residuals of large data, block by block, with a block-wise Jacobian."""
    pose = meas.kind == "pose"
    p_ref = meas.p if meas.kind != "sensor" else None
    x = params.copy()

    def rows_fn(
        sl: slice, inp: ModelInputs, jacobian: bool, products: bool, raw: bool
    ) -> tuple[Float, Float | None, Float, Float | None]:
        out = model.evaluate(
            x, inp, orientation=pose, jacobian=jacobian, products=products
        )
        if p_ref is not None:
            ref = p_ref[sl]
        else:
            assert meas.targets is not None and meas.target_index is not None
            ref = meas.targets[meas.target_index[sl]]
        return whiten(
            out,
            ref,
            None if meas.R_user_cam is None else meas.R_user_cam[sl],
            weights.sigma[sl],
            None if weights.sigma_rot is None else weights.sigma_rot[sl],
            jacobian,
            whiten_jacobian=not raw,
        )

    c = meas.components
    n_all = model.size + len(model.link_products)
    # Point and sensor rows are whitened by one factor each: the normal equations apply
    # it on the way, to the columns they use (pose rows are turned, too: no raw form).
    scale = None if pose else 1.0 / weights.sigma
    bj = BlockJacobian(rows_fn, inputs, c, model.size, n_all, scale)
    N = meas.n
    r = np.empty((N, c))
    e_p = np.empty((N, 3))
    e_r = np.empty((N, 3)) if pose else None
    for sl, rb, eb, erb in bj.residual_blocks():
        r[sl], e_p[sl] = rb, eb
        if e_r is not None:
            e_r[sl] = erb
    bj.r = r
    return ResidualBlock(r, None, e_p, e_r, None, bj)


def errors_mm(block: ResidualBlock) -> Float:
    """3-D position error norm of every row [mm]."""
    return np.linalg.norm(block.raw_position, axis=1) * 1e3
