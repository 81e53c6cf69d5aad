"""Sphere fitting: algebraic start, geometric Levenberg-Marquardt, outlier rejection.

The algebraic fit (``|p|² = 2 c·p + (R² - |c|²)``, linear in ``c`` and the constant) is
exact for noise-free points and a good start otherwise; it is biased for small caps, so
the geometric fit minimises the orthogonal distances ``|p_i - c| - R``. Outliers are
points further than ``k`` robust standard deviations (1.4826 MAD) from the surface; they
are flagged, the fit is repeated on the rest until the inlier set stops changing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import DataError
from kinecal.typing import Float

__all__ = ["SphereFit", "fit_sphere"]


@dataclass(frozen=True)
class SphereFit:
    """Result of :func:`fit_sphere`; lengths in the unit of the input points."""

    center: Float
    radius: float
    rms: float  # RMS orthogonal distance of the inliers
    n: int  # inliers used
    inliers: np.ndarray  # bool (N,)
    covariance: Float  # (4, 4) of (cx, cy, cz, R); (3, 3) when the radius was fixed
    iterations: int

    @property
    def center_std(self) -> Float:
        return np.sqrt(np.diag(self.covariance)[:3])

    @property
    def n_outliers(self) -> int:
        return int(self.inliers.size - self.n)


# Internally the points are pose-last, ``(3, N)``: every operation runs over contiguous
# rows of N numbers.


def _sq_norms(Q: Float) -> Float:
    """Squared lengths (N,) of the columns of Q (3, N)."""
    return Q[0] * Q[0] + Q[1] * Q[1] + Q[2] * Q[2]


def _gram(X: Float) -> Float:
    """``X Xᵀ`` for a few long rows X (k, N) by dot products of rows (BLAS's matrix
    product is several times slower for a 3x3 or 4x4 result)."""
    k = X.shape[0]
    G = np.empty((k, k))
    for i in range(k):
        for j in range(i, k):
            G[i, j] = G[j, i] = X[i] @ X[j]
    return G


def _algebraic(Q: Float) -> tuple[Float, float]:
    """Kasa's fit ``|p|^2 = 2 c·p + (R^2 - |c|^2)`` by normal equations (``Q`` (3, N)
    centred and scaled to unit RMS, so the 4x4 system is well conditioned)."""
    A = np.empty((4, Q.shape[1]))
    A[:3] = 2.0 * Q
    A[3] = 1.0
    rhs = _sq_norms(Q)
    sol = np.asarray(np.linalg.solve(_gram(A), A @ rhs), np.float64)
    c = sol[:3]
    r2 = sol[3] + c @ c
    return c, float(np.sqrt(max(r2, 0.0)))


def _normal(u: Float, r: Float, npar: int) -> tuple[Float, Float]:
    """``JᵀJ`` and ``Jᵀr`` for ``J = [-uᵀ, -1]`` (u the (3, N) unit directions) without
    forming ``J``."""
    JtJ = np.empty((npar, npar))
    JtJ[:3, :3] = _gram(u)
    g = np.empty(npar)
    g[:3] = -(u @ r)
    if npar == 4:
        su = u.sum(axis=1)
        JtJ[:3, 3] = JtJ[3, :3] = su
        JtJ[3, 3] = u.shape[1]
        g[3] = -r.sum()
    return JtJ, g


def _columns(Q: Float, keep: np.ndarray) -> Float:
    """The points ``keep`` selects, with contiguous rows (a boolean index on the last
    axis alone would give strided ones)."""
    return np.ascontiguousarray(Q[:, keep])


def _distances(Q: Float, c: Float) -> tuple[Float, Float]:
    """Distances (N,) of the points Q (3, N) from c, and the offsets Q - c (3, N)."""
    d = Q - c[:, None]
    return np.sqrt(_sq_norms(d)), d


def _geometric(
    Q: Float, c: Float, R: float, fixed_radius: float | None, max_iter: int = 50
) -> tuple[Float, float, Float, int]:
    """Gauss-Newton with Levenberg damping on the orthogonal distances.

    ``Q`` (3, N) is in normalised units (unit RMS about its mean): a step below 1e-7 of
    that is far under any measurable change, so it ends the iteration.
    """
    npar = 3 if fixed_radius is not None else 4
    x = np.append(c, R if fixed_radius is None else fixed_radius)

    def resid(xx: Float) -> tuple[Float, Float]:
        dist, d = _distances(Q, xx[:3])
        d /= np.maximum(dist, 1e-300)
        return dist - xx[3], d

    r, u = resid(x)
    cost = float(r @ r)
    mu = 1e-3
    it = 0
    JtJ, g = _normal(u, r, npar)
    for it in range(1, max_iter + 1):
        while True:
            step = -np.linalg.solve(JtJ + mu * np.diag(np.diag(JtJ)), g)
            x_new = x.copy()
            x_new[:npar] += step
            r_new, u_new = resid(x_new)
            cost_new = float(r_new @ r_new)
            if cost_new <= cost:
                mu = max(mu / 10.0, 1e-12)
                break
            mu *= 10.0
            if mu > 1e12:
                return x[:3], float(x[3]), JtJ, it
        done = cost - cost_new <= 1e-12 * cost or np.linalg.norm(step) <= 1e-7
        x, r, u, cost = x_new, r_new, u_new, cost_new
        JtJ, g = _normal(u, r, npar)
        if done:
            break
    return x[:3], float(x[3]), JtJ, it


def _rounds(
    Q: Float,
    c: Float,
    R: float,
    fixed: float | None,
    outlier_k: float | None,
    max_rounds: int,
    min_points: int,
    inl: np.ndarray | None = None,
) -> tuple[Float, float, Float, np.ndarray, int, Float]:
    """Geometric fits alternating with MAD outlier rejection until the inliers settle.

    Returns the sphere, ``JᵀJ`` at it, the inliers, the iterations and the signed
    distances (N,) of every point from the final sphere."""
    inl = np.ones(Q.shape[1], bool) if inl is None else inl
    iters = 0
    JtJ = np.eye(3 if fixed is not None else 4)
    d = np.zeros(0)
    for _ in range(max_rounds):
        c, R, JtJ, it = _geometric(Q if inl.all() else _columns(Q, inl), c, R, fixed)
        iters += it
        d = _distances(Q, c)[0] - R
        if outlier_k is None:
            break
        di = d[inl]
        sig = 1.4826 * float(np.median(np.abs(di - np.median(di))))
        new = np.abs(d) <= outlier_k * max(sig, 1e-12)
        if new.sum() < max(min_points, 4):
            raise DataError(
                f"fit_sphere: only {int(new.sum())} of {Q.shape[1]} points lie on one sphere"
            )
        if np.array_equal(new, inl):
            break
        inl = new
    return c, R, JtJ, inl, iters, d


def fit_sphere(
    points: Float,
    *,
    radius: float | None = None,
    outlier_k: float | None = 4.0,
    max_rounds: int = 10,
    min_points: int = 10,
) -> SphereFit:
    """Fit a sphere to ``points`` (N, 3).

    ``radius`` fixes the radius (a calibrated sphere: only the centre is estimated).
    ``outlier_k`` is the rejection threshold in robust standard deviations (``None``: keep
    every point). The covariance is ``s² (JᵀJ)⁻¹`` at the solution, ``s`` the RMS of the
    inliers corrected for the degrees of freedom.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise DataError(f"fit_sphere: points must be (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        bad = int(np.flatnonzero(~np.isfinite(P).all(axis=1))[0])
        raise DataError(f"fit_sphere: point {bad} is not finite")
    if P.shape[0] < max(min_points, 4):
        raise DataError(
            f"fit_sphere: need at least {max(min_points, 4)} points, got {P.shape[0]}"
        )
    if radius is not None and not radius > 0:
        raise DataError(f"fit_sphere: radius must be positive, got {radius}")
    Q = np.array(P.T, order="C")  # (3, N), contiguous rows
    origin = Q.mean(axis=1)
    Q -= origin[:, None]
    scale = float(np.sqrt(np.mean(_sq_norms(Q)))) or 1.0
    Q /= scale
    fixed = None if radius is None else radius / scale
    # Large clouds: the whole robust fit first runs on an evenly strided subset of about
    # 10k points; its sphere and noise level classify every point, and the final rounds
    # (which decide the result) use all points from there.
    stride = max(1, P.shape[0] // 10_000)
    Qs = np.ascontiguousarray(Q[:, ::stride])
    c, R = _algebraic(Qs)
    inl = np.ones(P.shape[0], bool)
    iters = 0
    if stride > 1:
        c, R, _, inl_s, it, _ = _rounds(
            Qs, c, R, fixed, outlier_k, max_rounds, min_points
        )
        iters += it
        if outlier_k is not None:
            d = _distances(Q, c)[0] - R
            ds = d[::stride][inl_s]
            sig = 1.4826 * float(np.median(np.abs(ds - np.median(ds))))
            inl = np.abs(d) <= outlier_k * max(sig, 1e-12)
            if inl.sum() < max(min_points, 4):
                raise DataError(
                    f"fit_sphere: only {int(inl.sum())} of {P.shape[0]} points lie on "
                    "one sphere"
                )
    c, R, JtJ, inl, it, d = _rounds(
        Q, c, R, fixed, outlier_k, max_rounds, min_points, inl
    )
    iters += it
    npar = JtJ.shape[0]
    d_in = d[inl]
    n = int(inl.sum())
    rms = float(np.sqrt(np.mean(d_in**2)))
    s2 = float(d_in @ d_in) / max(n - npar, 1)
    try:
        cov = np.linalg.inv(JtJ) * s2
    except np.linalg.LinAlgError:
        cov = np.full((npar, npar), np.inf)
    return SphereFit(
        center=c * scale + origin,
        radius=float(R * scale),
        rms=rms * scale,
        n=n,
        inliers=inl,
        covariance=np.asarray(cov * scale**2, dtype=float),
        iterations=iters,
    )
