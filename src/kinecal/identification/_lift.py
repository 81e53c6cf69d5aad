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
    LMOptions,
    NormalSource,
    Prior,
    normal_of,
    solve_lm,
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
    stol, s0sq : the statistical stop of the small bilinear fit at the end
        (:class:`LMOptions`) and the data's variance of unit weight it compares with:
        the start need not be closer to that fit's optimum than the stage's own LM
        would resolve. 0 (default): to convergence.

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
    evals, evecs = np.linalg.eigh(A)
    keep = evals > max(float(evals.max()), 0.0) * 1e-13
    U = np.sqrt(evals[keep])[:, None] * evecs[:, keep].T  # A = U'U on its range
    c0 = (evecs[:, keep].T @ g) / np.sqrt(evals[keep])  # so that U'c0 = g

    def quadratic(xx: Float, jac: bool) -> tuple[Float, Float | None]:
        mu_x = np.array([xx[lam] * xx[s] for _, lam, s in pairs])
        d = (np.concatenate([xx[native], mu_x]) - z0) / sc_l
        res = (U @ d + c0)[:, None]
        if not jac:
            return res, None
        D = np.zeros((cols.size, P))  # d (lifted, scaled) / d x
        D[np.arange(native.size), native] = 1.0 / sc_l[: native.size]
        for k, (_, lam, s) in enumerate(pairs):
            D[native.size + k, lam] = xx[s] / sc_mu[k]
            D[native.size + k, s] = xx[lam] / sc_mu[k]
        return res, (U @ D)[:, None, :]

    fit = solve_lm(
        quadratic,
        x1,
        free,
        scales,
        LMOptions(max_iter=200, stol=stol),
        prior=prior,
        label="lift",
        s0sq=s0sq,
    )
    return fit.x


def _product_sigma(m1: float, s1: float, m2: float, s2: float) -> float:
    """Standard deviation of the product of independent N(m1, s1^2) and N(m2, s2^2);
    ``inf`` when a factor has no prior."""
    if not (np.isfinite(s1) and np.isfinite(s2)):
        return np.inf
    return float(np.sqrt((s1 * s1 + m1 * m1) * (s2 * s2 + m2 * m2) - (m1 * m2) ** 2))
