"""Start of the compliance fit by one linear solve in product coordinates.

The link self-weight enters the joint deflections as products of two parameters,
``delta theta_j = lambda*_j (tau_F,j + sum_k s_k T_jk)`` (Eq. 24-26), so the cost is
strongly curved in ``(lambda*, s)``: from the stage-2 point (``lambda* = s = 0``, where
the kinematic and transmission parameters have absorbed the link weight) to the optimum,
the products switch on quadratically while the absorbing parameters unwind linearly, and
a Levenberg-Marquardt run needs dozens of short steps down the curved valley.

In the lifted coordinates ``mu_jk = lambda*_j s_k`` the deflection, and with it the model
to first order in the (tiny) deflection, is linear. One Gauss-Newton step there lands next
to the optimum; the point of the ``(lambda*, s)`` manifold that minimises the same
quadratic model plus the exact priors is then a start from which Gauss-Newton converges
in a few steps. This replaces a start, never the fit: the final LM run on the model's
own parameters decides the result.
"""

from __future__ import annotations

import numpy as np

from kinecal.identification._lm import (
    NormalSource,
    Prior,
    normal_of,
    spd_solve,
)
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = ["lifted_start"]


def lifted_start(
    model: CalibrationModel,
    x: Float,
    r: Float,
    J: Float | NormalSource,
    free: np.ndarray,
    prior: Prior | None,
    row_weights: Float | None = None,
    *,
    stol: float = 0.0,
    s0sq: float | None = None,
) -> Float:
    """Parameters from one Gauss-Newton step in product coordinates, mapped back.

    Parameters
    ----------
    model : CalibrationModel
    x : (P,) the point of linearisation (any point; the stage-2 result or a previous fit).
    r : (N, c) whitened residuals at ``x``.
    J : (N, c, P + K) their Jacobian with the product columns of
        :attr:`CalibrationModel.link_products` (``evaluate(..., products=True)``), or a
        block-wise one (:class:`~kinecal.identification._lm.NormalSource`).
    free : (P,) bool, the estimated parameters.
    prior : Prior or None
    row_weights : (N,) square roots of robust row weights, or None.
    stol, s0sq : the stage's statistical stop (:class:`~._lm.LMOptions`) and the data's
        variance of unit weight: the small bilinear problem at the end stops when its
        next step would lower the cost by less than ``1e-3 stol s0sq``, far below what
        the stage's own LM resolves. 0 (default): to round-off.

    Returns
    -------
    ndarray (P,)
        ``x`` itself when the model has no product of two estimated parameters.
    """
    P = model.size
    scales = model.layout.scales
    pairs = [
        (P + i, lam, s)
        for i, (lam, s) in enumerate(model.link_products)
        if free[lam] and free[s]
    ]
    if not pairs:
        return x
    lifted = np.zeros(P, bool)
    lifted[[s for _, _, s in pairs]] = True
    native = np.flatnonzero(free & ~lifted)
    cols = np.concatenate([native, [c for c, _, _ in pairs]])
    sc_mu = np.array([scales[lam] * scales[s] for _, lam, s in pairs])
    sc_l = np.concatenate([scales[native], sc_mu])
    A, g = normal_of(r, J, cols, sc_l, row_weights)

    # At a point of the manifold the lifted column of lambda*_j is the model's column
    # minus sum_k s_k (column of mu_jk): change of variables T, A -> T' A T.
    T = np.eye(cols.size)
    pos = {int(i): k for k, i in enumerate(native)}
    for k, (_, lam, s) in enumerate(pairs):
        T[native.size + k, pos[lam]] = -x[s] / scales[s]
    A = T.T @ A @ T
    g = T.T @ g

    # Lifted priors: the model's on the native parameters; on mu = lambda* s the moments
    # of a product of independent Gaussians.
    pr = prior or Prior.none(P)
    mean_l = np.concatenate(
        [pr.mean[native], [pr.mean[lam] * pr.mean[s] for _, lam, s in pairs]]
    )
    sigma_mu = [
        _product_sigma(pr.mean[lam], pr.sigma[lam], pr.mean[s], pr.sigma[s])
        for _, lam, s in pairs
    ]
    sigma_l = np.concatenate([pr.sigma[native], sigma_mu])
    prec = np.where(np.isfinite(sigma_l), (sc_l / sigma_l) ** 2, 0.0)
    z0 = np.concatenate([x[native], [x[lam] * x[s] for _, lam, s in pairs]])
    step = spd_solve(A + np.diag(prec), g + prec * (z0 - mean_l) / sc_l, rcond=1e-13)
    z = z0 - step * sc_l

    # Back to the model's parameters: lambda* as found, each s_k from its products by
    # least squares, then the point of the manifold that minimises the same quadratic
    # model of the data plus the model's own priors (a small bilinear problem).
    x1 = x.copy()
    x1[native] = z[: native.size]
    mu = z[native.size :]  # Eq. (T-2): mu_jk = lambda*_j s_k
    for i_s in np.flatnonzero(lifted):
        ks = [k for k, (_, _, ss) in enumerate(pairs) if ss == i_s]
        lams = x1[[pairs[k][1] for k in ks]]
        if lams @ lams > 0.0:
            x1[i_s] = float(lams @ mu[ks]) / float(lams @ lams)
    s_idx = np.flatnonzero(lifted)
    tol = 1e-3 * stol * (s0sq if s0sq is not None else 1.0)
    return _project(x, x1, native, s_idx, pairs, scales, A, g, pr, tol)


def _project(
    x: Float,
    x1: Float,
    native: np.ndarray,
    s_idx: np.ndarray,
    pairs: list[tuple[int, int, int]],
    scales: Float,
    A: Float,
    g: Float,
    pr: Prior,
    tol: float,
) -> Float:
    """The minimum of the lifted quadratic model ``1/2 dᵀAd + dᵀg`` plus the model's own
    priors over the ``(lambda*, s)`` manifold, near the link moments of ``x1``.

    ``d`` is the scaled offset from the linearisation point of the lifted coordinates:
    ``x[native]`` and ``x[lam] x[s]`` of every pair. For fixed link moments ``s`` the
    model is linear in every other parameter, so those are eliminated exactly (variable
    projection, Golub & Pereyra 1973, Eq. (T-11)); Newton's method with the exact reduced
    Hessian then runs on the few ``s`` alone and converges in a few steps, where
    Levenberg-Marquardt on all parameters crept down the bilinear valley for 40-50
    (Gauss-Newton drops the valley's curvature, the products' second derivatives).
    It stops when the next step would lower the cost by at most ``tol``.
    """
    n, m, q = native.size, len(pairs), s_idx.size
    sc_n, sc_s = scales[native], scales[s_idx]
    pos = {int(i): k for k, i in enumerate(native)}
    a = np.array([pos[lam] for _, lam, _ in pairs])  # lambda*_j of pair k: u[a[k]]
    spos = {int(i): k for k, i in enumerate(s_idx)}
    b = np.array([spos[s] for _, _, s in pairs])  # s of pair k: v[b[k]]
    lam0 = x[[lam for _, lam, _ in pairs]]
    mu0 = lam0 * x[[s for _, _, s in pairs]]
    sc_lam = scales[[lam for _, lam, _ in pairs]]
    sc_mu = sc_lam * sc_s[b]
    # Priors in the scaled offsets u = (x[native] - x) / sc, v = (x[s] - x1[s]) / sc.
    fin_n, fin_s = np.isfinite(pr.sigma[native]), np.isfinite(pr.sigma[s_idx])
    Pn = np.where(fin_n, (sc_n / pr.sigma[native]) ** 2, 0.0)
    Ps = np.where(fin_s, (sc_s / pr.sigma[s_idx]) ** 2, 0.0)
    um = np.where(fin_n, (pr.mean[native] - x[native]) / sc_n, 0.0)
    vm = np.where(fin_s, (pr.mean[s_idx] - x1[s_idx]) / sc_s, 0.0)
    Ann, Anm, Amm = A[:n, :n], A[:n, n:], A[n:, n:]
    rows = np.arange(m)

    def inner(v: Float) -> tuple[float, Float, Float, Float]:
        """phi(v) = min over u, that u, phi's gradient and its Hessian in v."""
        s = x1[s_idx] + sc_s * v
        # d = [u; C u + e0]: the products' rows, linear in u for these s.
        C = np.zeros((m, n))
        C[rows, a] = s[b] / sc_s[b]
        e0 = (lam0 * s[b] - mu0) / sc_mu
        AC = Anm @ C
        Luu = Ann + AC + AC.T + C.T @ Amm @ C + np.diag(Pn)
        rhs = -(g[:n] + C.T @ g[n:] + Anm @ e0 + C.T @ (Amm @ e0)) + Pn * um
        u = spd_solve(Luu, rhs, rcond=1e-13)
        d = np.concatenate([u, C @ u + e0])
        res = A @ d + g  # the gradient of the data part in d
        lam = lam0 + sc_lam * u[a]
        Dv = np.zeros((n + m, q))  # d d / d v: only the products' rows
        Dv[n + rows, b] = lam / sc_lam
        phi = 0.5 * d @ (A @ d) + d @ g + 0.5 * Pn @ (u - um) ** 2
        phi += 0.5 * Ps @ (v - vm) ** 2
        grad = Dv.T @ res + Ps * (v - vm)
        # Hessian of the joint cost: the v block, and the u-v block with the products'
        # own second derivative (d^2 d_k / du dv = 1 in these units).
        Luv = np.concatenate([np.eye(n), C]).T @ (A @ Dv)
        np.add.at(Luv, (a, b), res[n:])
        Hvv = Dv.T @ A @ Dv + np.diag(Ps)
        H = Hvv - Luv.T @ spd_solve(Luu, Luv, rcond=1e-13)  # Eq. (T-11)
        return float(phi), u, grad, 0.5 * (H + H.T)

    v = np.zeros(q)
    phi, u, grad, H = inner(v)
    for _ in range(30):
        evals, evecs = np.linalg.eigh(H)
        big = max(float(np.abs(evals).max()), 1e-300)
        keep = np.abs(evals) > 1e-12 * big
        if not keep.any():
            break
        # Newton's step, with the curvature's sign turned where it is negative (a saddle
        # is left, not climbed to).
        c = evecs[:, keep].T @ grad
        step = -evecs[:, keep] @ (c / np.abs(evals[keep]))
        pred = -(grad @ step + 0.5 * step @ (H @ step))
        if not np.isfinite(pred) or pred <= max(tol, 1e-13 * (abs(phi) + 1.0)):
            break
        t = 1.0
        for _ in range(40):  # backtracking (Armijo)
            trial = inner(v + t * step)
            if trial[0] <= phi + 1e-4 * t * (grad @ step):
                break
            t *= 0.5
        else:
            break
        v = v + t * step
        phi, u, grad, H = trial
    out = x.copy()
    out[native] = x[native] + sc_n * u
    out[s_idx] = x1[s_idx] + sc_s * v
    return out


def _product_sigma(m1: float, s1: float, m2: float, s2: float) -> float:
    """Standard deviation of the product of independent N(m1, s1^2) and N(m2, s2^2);
    ``inf`` when a factor has no prior."""
    if not (np.isfinite(s1) and np.isfinite(s2)):
        return np.inf
    return float(np.sqrt((s1 * s1 + m1 * m1) * (s2 * s2 + m2 * m2) - (m1 * m2) ** 2))
