"""The uncertainty of the estimate: ``cov = s0^2 (J^T W J + P)^-1`` at the solution
(Eq. (T-3)), the standard deviations and ``s0``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.identification._diagnostics import Diagnostic
from kinecal.identification._lm import loss_weights, psd_inverse
from kinecal.identification._problem import Problem, State
from kinecal.identification._residuals import ResidualBlock
from kinecal.typing import Float

__all__ = ["Uncertainty"]


@dataclass(frozen=True)
class Uncertainty:
    """Covariance ``s0^2 (J^T W J + P)^-1`` of the free parameters at the solution
    (``W``: robust row weights, ``P``: prior precision; Eq. (T-3)), their standard
    deviations and the a-posteriori standard deviation of unit weight ``s0``."""

    name: str = "uncertainty"

    def __call__(self, problem: Problem, state: State) -> State:
        cm, lm = state.model, state.lm
        fidx = np.flatnonzero(state.free)
        scales = cm.layout.scales[fidx]
        blk = problem.evaluations(cm, state.x, state.weights, jacobian=True)
        wr = loss_weights(np.sum(blk.r**2, axis=1) / lm.f_scale**2, lm.loss)[1]
        dof = problem.n_residuals - fidx.size
        sigma0 = float(np.sqrt(np.sum(wr[:, None] * blk.r**2) / max(dof, 1)))
        sw = None if lm.loss == "linear" else np.sqrt(wr)
        A, _ = blk.normal(fidx, scales, sw)
        prior = state.active_prior()
        prec = (
            np.zeros(fidx.size) if prior is None else prior.precision[fidx] * scales**2
        )
        A = A + np.diag(prec)
        cov = np.zeros((cm.size, cm.size))
        found = []
        try:
            Ai = psd_inverse(A, 1e-14)
            if state.noise is None:
                cov_f = sigma0**2 * Ai  # Eq. (T-3)
            else:
                # The data are weighed otherwise than their noise (orientations
                # down-weighted): the sandwich A^-1 (J^T W S W J + P) A^-1 with the noise S.
                meat = _meat(blk, fidx, scales, state)
                cov_f = Ai @ (meat + np.diag(prec)) @ Ai
            cov[np.ix_(fidx, fidx)] = cov_f * np.outer(scales, scales)
        except np.linalg.LinAlgError:
            found.append(
                Diagnostic(
                    "no_covariance",
                    "the normal matrix could not be inverted; no standard deviations.",
                    stage=self.name,
                )
            )
        std = np.full(cm.size, np.nan)
        std[fidx] = np.sqrt(np.clip(np.diag(cov)[fidx], 0.0, None))
        return state.but(covariance=cov, std=std, sigma0=sigma0).note(*found)


def _meat(blk: ResidualBlock, fidx: np.ndarray, scales: Float, state: State) -> Float:
    """``J^T W S W J`` (scaled): the whitened Jacobian rows times the ratio of each
    component's noise variance to its weighting variance (by blocks of poses for large
    data)."""
    assert state.noise is not None
    w, s = state.weights, state.noise
    ratio = [s.sigma / w.sigma] * 3
    if w.sigma_rot is not None and s.sigma_rot is not None:
        ratio += [s.sigma_rot / w.sigma_rot] * 3
    R = np.stack(ratio, axis=1)  # (N, c)
    if blk.J is not None:
        Js = blk.J[:, :, fidx] * scales * R[:, :, None]
        Jf = Js.reshape(-1, fidx.size)
        return Jf.T @ Jf
    out = np.zeros((fidx.size, fidx.size))
    for rows, J in blk.jacobian_blocks():
        Jf = (J[:, :, fidx] * scales * R[rows, :, None]).reshape(-1, fidx.size)
        out += Jf.T @ Jf
    return out
