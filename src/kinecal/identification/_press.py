"""Leave-one-out prediction errors of a fit, without refitting (PRESS).

At the solution the model is linear to first order: with the whitened, scaled Jacobian
``J`` of the free parameters and the prior precision ``P``, the hat matrix is
``H = J (JᵀJ + P)⁻¹ Jᵀ`` and the residual row ``i`` would have had, had the fit left it
out, ``r_(i) = (I − H_ii)⁻¹ r_i`` (``H_ii`` its c×c block; Eq. (T-5)). Their root mean
square over the position components predicts the cross-validated error; kinecal uses it to
weigh orientations against positions (:class:`~kinecal.identification.NoiseModel`) and to
check that a rejection helps the prediction of the other rows
(:class:`~kinecal.identification.RobustRejection`).
"""

from __future__ import annotations

import numpy as np

from kinecal.identification._problem import Problem, State
from kinecal.measurement._residuals import Weights
from kinecal.typing import Float

__all__ = ["loo_position_errors"]

_CHUNK = 20000  # rows per block of the hat-matrix diagonal


def loo_position_errors(
    problem: Problem, state: State, weights: Weights | None = None
) -> Float:
    """Leave-one-out position errors (N, 3) [m] of the rows of ``problem``.

    With ``weights`` other than the state's, the fit is first moved by one Gauss-Newton
    step to where those weights put it (linearised at the state's parameters).
    """
    cm = state.model
    w = state.weights if weights is None else weights
    blk = problem.evaluations(cm, state.x, w, jacobian=True)
    fidx = np.flatnonzero(state.free)
    sc = cm.layout.scales[fidx]
    N, c = blk.r.shape
    if blk.J is not None:
        A = np.zeros((fidx.size, fidx.size))
        g = np.zeros(fidx.size)
        for lo in range(0, N, _CHUNK):
            J = blk.J[lo : lo + _CHUNK][:, :, fidx] * sc
            Jf = J.reshape(-1, fidx.size)
            A += Jf.T @ Jf
            g += Jf.T @ blk.r[lo : lo + _CHUNK].reshape(-1)
    else:  # large data: summed by blocks of poses (shared with other products)
        A, g = blk.normal(fidx, sc)
    prior = state.active_prior()
    if prior is not None:
        prec = prior.precision[fidx] * sc**2
        A += np.diag(prec)
        g += prec * (state.x[fidx] - prior.mean[fidx]) / sc
    Ai = np.linalg.pinv(A, rcond=1e-12, hermitian=True)
    dz = -Ai @ g if weights is not None else np.zeros(fidx.size)
    out = np.empty((N, 3))
    eye = np.eye(c)
    for rows, Jb in blk.jacobian_blocks(_CHUNK):
        J = Jb[:, :, fidx] * sc
        r = blk.r[rows] + J @ dz
        H = np.einsum("nip,pq,njq->nij", J, Ai, J)
        r_loo = np.linalg.solve(eye - H, r[:, :, None])[:, :, 0]  # Eq. (T-5)
        out[rows] = r_loo[:, :3] * w.sigma[rows, None]
    return out


def rms_mm(e: Float) -> float:
    """RMS of 3-D error norms [mm] of errors (N, 3) [m]."""
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1)))) * 1e3
