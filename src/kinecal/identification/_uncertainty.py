"""The uncertainty of the estimate: ``cov = s0^2 (J^T W J + P)^-1`` at the solution
(Eq. (T-3)), the standard deviations and ``s0``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.identification._lm import loss_weights, psd_inverse
from kinecal.identification._problem import Problem, State
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._residuals import ResidualBlock
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
        jack = None
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
            jack = _jackknife(problem, blk, fidx, scales, wr, Ai)
            if jack is not None:  # never below the spread over left-out poses
                sd = np.sqrt(np.clip(np.diag(cov_f), 0.0, None))
                wide = np.maximum(sd, np.sqrt(jack))
                ratio = np.divide(wide, sd, out=np.ones_like(sd), where=sd > 0)
                cov_f = cov_f * np.outer(ratio, ratio)
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


# The jackknife over left-out poses runs up to this many poses (one small solve each).
_JACKKNIFE_POSES = 5000


def _jackknife(
    problem: Problem,
    blk: ResidualBlock,
    fidx: np.ndarray,
    scales: Float,
    wr: Float,
    Ai: Float,
) -> Float | None:
    """The jackknife variance of each free parameter (scaled units) over left-out poses:
    the fit without pose g one Gauss-Newton step from the solution on the downdated
    normal equations, ``d_g = (A - J_g^T J_g)^-1 J_g^T r_g`` (Woodbury with ``A^-1``),
    and ``(G-1)/G sum (d_g - mean d)^2``. It sees what the row-by-row covariance does not:
    residuals of a pose that move together (several markers), effects the model lacks.
    None where it is not formed: fewer than 10 or more than :data:`_JACKKNIFE_POSES`
    poses, or the rows of a pose not next to each other in the data."""
    meas = problem.meas
    if meas.n != blk.r.shape[0]:
        return None
    g = meas.pose_groups()
    G = int(g.max()) + 1 if g.size else 0
    if not 10 <= G <= _JACKKNIFE_POSES or np.any(np.diff(g) < 0):
        return None
    sw = np.sqrt(wr)[:, None]
    r = blk.r * sw
    parts: list[Float] = []
    carry: tuple[Float, np.ndarray] | None = None  # rows of a pose a block cut
    try:
        for rows, J in blk.jacobian_blocks():
            Js = J[:, :, fidx] * scales * sw[rows, :, None]  # whitened, scaled
            idx = np.arange(blk.r.shape[0])[rows]
            if carry is not None:
                Js, idx = (
                    np.concatenate([carry[0], Js]),
                    np.concatenate([carry[1], idx]),
                )
            last = idx[-1] == blk.r.shape[0] - 1
            cut = idx.size if last else int(np.searchsorted(g[idx], g[idx[-1]]))
            carry = None if last else (Js[cut:], idx[cut:])
            if cut:
                parts.append(_steps(Js[:cut], r[idx[:cut]], g[idx[:cut]], Ai))
    except np.linalg.LinAlgError:  # a pose the others cannot do without
        return None
    d = np.concatenate(parts)
    d -= d.mean(axis=0)
    return (G - 1) / G * np.sum(d**2, axis=0)


def _steps(Js: Float, r: Float, g: np.ndarray, Ai: Float) -> Float:
    """The leave-one-pose-out steps ``d_g`` of the poses whose rows these are (sorted by
    pose): one batched solve when every pose has as many rows, else one per pose."""
    bounds = np.flatnonzero(np.r_[True, g[1:] != g[:-1], True])
    sizes = np.diff(bounds)
    G, k = sizes.size, Js.shape[2]
    if np.all(sizes == sizes[0]):
        m = int(sizes[0]) * Js.shape[1]
        Jg = Js.reshape(G, m, k)
        u = np.einsum("gmk,gm->gk", Jg, r.reshape(G, m)) @ Ai  # (A symmetric)
        JA = Jg @ Ai  # (G, m, k)
        H = np.eye(m) - JA @ Jg.transpose(0, 2, 1)
        w = np.linalg.solve(H, np.einsum("gmk,gk->gm", Jg, u)[..., None])[..., 0]
        return u + np.einsum("gmk,gm->gk", JA, w)
    d = np.empty((G, k))
    for i in range(G):  # one small solve per pose (its rows x components)
        sl = slice(bounds[i], bounds[i + 1])
        Jg1 = Js[sl].reshape(-1, k)
        u1 = Ai @ (Jg1.T @ r[sl].reshape(-1))
        H1 = np.eye(Jg1.shape[0]) - Jg1 @ Ai @ Jg1.T
        d[i] = u1 + Ai @ Jg1.T @ np.linalg.solve(H1, Jg1 @ u1)
    return d


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
