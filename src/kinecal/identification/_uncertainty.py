"""The uncertainty of the estimate: ``cov = s0^2 (J^T W J + P)^-1`` at the solution
(Eq. (T-3)), the standard deviations and ``s0``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal._record import Record
from kinecal.identification._lm import loss_weights, psd_inverse
from kinecal.identification._normal import block_normal
from kinecal.identification._problem import Problem, State
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._residuals import ResidualBlock
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = ["Uncertainty"]


@dataclass(frozen=True, eq=False, repr=False)
class Uncertainty(Record):
    """Covariance ``s0^2 (J^T W J + P)^-1`` of the free parameters at the solution
    (``W``: robust row weights, ``P``: prior precision; Eq. (T-3)), their standard
    deviations and the a-posteriori standard deviation of unit weight ``s0``.
    ``covariance=False``: ``s0`` alone, from the residuals (no Jacobian pass; the
    standard deviations NaN), for a fit whose standard deviations nobody reads (the
    nominal check's screen)."""

    name: str = "uncertainty"
    covariance: bool = True

    def __call__(self, problem: Problem, state: State) -> State:
        cm, lm = state.model, state.lm
        fidx = np.flatnonzero(state.free)
        scales = cm.layout.scales[fidx]
        want = self.covariance
        blk = problem.evaluations(cm, state.x, state.weights, jacobian=want)
        wr = loss_weights(np.sum(blk.r**2, axis=1) / lm.f_scale**2, lm.loss)[1]
        dof = problem.n_residuals - fidx.size
        sigma0 = float(np.sqrt(np.sum(wr[:, None] * blk.r**2) / max(dof, 1)))
        if not want:
            return state.but(
                covariance=np.zeros((cm.size, cm.size)),
                std=np.full(cm.size, np.nan),
                sigma0=sigma0,
            )
        sw = None if lm.loss == "linear" else np.sqrt(wr)
        A, _ = block_normal(blk, fidx, scales, sw)
        prior = state.active_prior()
        prec = (
            np.zeros(fidx.size) if prior is None else prior.precision[fidx] * scales**2
        )
        A = A + np.diag(prec)
        cov = np.zeros((cm.size, cm.size))
        std = np.full(cm.size, np.nan)  # no covariance: no std (null), not 0
        found = []
        try:
            Ai = psd_inverse(A, 1e-14)
            # The posterior covariance in two parts (Eq. (T-3c)): what the data leave,
            # Ai (J^T W J) Ai, and what the prior holds, Ai P Ai.
            if state.noise is None:
                data = sigma0**2 * (Ai @ (A - np.diag(prec)) @ Ai)  # Eq. (T-3)
                held = sigma0**2 * (Ai * prec) @ Ai
            else:
                # The data are weighed otherwise than their noise (orientations
                # down-weighted): the sandwich A^-1 (J^T W S W J + P) A^-1 with the noise S.
                data = Ai @ _meat(blk, fidx, scales, state) @ Ai
                held = (Ai * prec) @ Ai
            cov_f = data + held
            jack = _jackknife(problem, blk, fidx, scales, wr, Ai)
            if jack is not None:  # never below the jackknife where it is clearly above
                cov_f = _widen(cov_f, *jack)
            cov[np.ix_(fidx, fidx)] = cov_f * np.outer(scales, scales)
            std[fidx] = np.sqrt(np.clip(np.diag(cov)[fidx], 0.0, None))
            found += _prior_dominated(
                cm, fidx, np.diag(held), np.diag(cov_f), self.name
            )
        except np.linalg.LinAlgError:
            found.append(
                Diagnostic(
                    "no_covariance",
                    "the normal matrix could not be inverted; no standard deviations.",
                    stage=self.name,
                )
            )
        return state.but(covariance=cov, std=std, sigma0=sigma0).note(*found)


# The jackknife over left-out poses runs up to this many poses (one small solve each).
_JACKKNIFE_POSES = 5000


def _prior_dominated(
    cm: CalibrationModel, fidx: np.ndarray, held: Float, total: Float, stage: str
) -> list[Diagnostic]:
    """``prior_dominated``: the parameters whose variance is more their prior's part
    than the data's (Eq. (T-3c)); the spread of their estimates over left-out poses
    cannot show their uncertainty (every refit is held alike)."""
    share = np.divide(held, total, out=np.zeros_like(held), where=total > 0)
    weak = [cm.layout.names[i] for i in fidx[share > 0.5]]
    if not weak:
        return []
    return [
        Diagnostic(
            "prior_dominated",
            f"{len(weak)} parameters are determined mostly by their prior, "
            f"not by the data: {', '.join(weak[:8])}"
            + (" ..." if len(weak) > 8 else "")
            + ".",
            parameters=tuple(weak),
            stage=stage,
        )
    ]


def _jackknife(
    problem: Problem,
    blk: ResidualBlock,
    fidx: np.ndarray,
    scales: Float,
    wr: Float,
    Ai: Float,
) -> tuple[Float, int] | None:
    """The jackknife covariance of the free parameters (scaled units) over left-out poses
    and the number of poses G:
    the fit without pose g one Gauss-Newton step from the solution on the downdated
    normal equations, ``d_g = (A - J_g^T J_g)^-1 J_g^T r_g`` (Woodbury with ``A^-1``),
    and ``(G-1)/G sum (d_g - mean d)(d_g - mean d)^T``. It sees what the row-by-row
    covariance does not: residuals of a pose that move together (several markers),
    effects the model lacks.
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
    return (G - 1) / G * (d.T @ d), G


def _widen(C: Float, Cj: Float, G: int) -> Float:
    """The covariance ``C`` widened to the jackknife's ``Cj`` (from ``G`` poses) in the
    directions where ``Cj`` is clearly larger (Eq. (T-3d)). With ``C = L Lᵀ`` and the
    eigenvectors ``V`` and values ``l`` of ``L⁻¹ Cj L⁻ᵀ``: ``L V l' Vᵀ Lᵀ`` with
    ``l' = l`` beyond the largest value chance gives when ``C`` is right (the
    Marchenko-Pastur edge ``(1 + sqrt(k / (G - 1)))²`` for k parameters), else 1.
    Direction by direction, not parameter by parameter: two correlated parameters
    widened alone by different factors would no longer cancel in a prediction. The
    result does not depend on the parameters' units."""
    k = C.shape[0]
    if k == 0:
        return C
    reg = 1e-9 * (np.diag(C) + max(float(np.trace(C)) / k, 1e-300))
    try:
        L = np.linalg.cholesky(C + np.diag(reg))
        M = np.linalg.solve(L, np.linalg.solve(L, Cj).T)
        lam, V = np.linalg.eigh(0.5 * (M + M.T))
    except np.linalg.LinAlgError:  # C not positive definite: left as it is
        return C
    edge = (1.0 + np.sqrt(k / max(G - 1, 1))) ** 2
    if not np.any(lam > edge):
        return C
    W = L @ V
    return (W * np.where(lam > edge, lam, 1.0)) @ W.T


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
