"""Sphere fitting: segmentation, geometric Levenberg-Marquardt, outliers, refusals.

A scan of a ceramic sphere also holds what surrounds it: the support plate, the stem,
neighbouring spheres. The sphere is segmented first by RANSAC: spheres through 4 points
drawn at random (the algebraic fit ``|p|² = 2 c·p + (R² - |c|²)``, linear in ``c`` and
the constant, exact through 4 points), with the known radius as a prior when given, are
scored on a subset of the cloud by the number of points within a band of the surface;
the best one seeds the fit. The geometric fit then minimises the orthogonal distances
``|p_i - c| - R`` (Gauss-Newton with Levenberg damping), alternating with the rejection
of points further than ``k`` robust standard deviations (1.4826 MAD) from the surface
until the inlier set stops changing.

Clouds that do not determine a sphere are refused: points on a line or a plane (one
circle is on a plane) by the singular values of the centred cloud, and clouds whose
curvature does not stand out of their noise (the sphere's RMS distance not clearly
below the best plane's). The result reports the centre's standard deviation (``s² (JᵀJ)⁻¹``
at the solution) and the half-angle of the cap the inliers cover.

All long reductions are dot products by ``einsum`` and the small systems LAPACK solves:
no BLAS call, so a fit runs on one thread whatever the BLAS thread setting (OpenBLAS
threads on dot products of 50 000 numbers slowed a 50k-point fit 3-13x on a busy 2-core
machine).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import DataError
from kinecal.typing import Float

__all__ = ["SphereFit", "fit_sphere"]

# RANSAC: points scored per hypothesis, hypotheses per batch, most hypotheses drawn.
_SCORE_POINTS = 1000
_BATCH = 128
_MAX_HYPOTHESES = 4096


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
    cap_half_angle: float = float("nan")  # [rad] half-angle of the cap the inliers span

    @property
    def center_std(self) -> Float:
        return np.sqrt(np.diag(self.covariance)[:3])

    @property
    def radius_std(self) -> float:
        return (
            float(np.sqrt(self.covariance[3, 3]))
            if self.covariance.shape[0] == 4
            else 0.0
        )

    @property
    def n_outliers(self) -> int:
        return int(self.inliers.size - self.n)


# Internally the points are pose-last, ``(3, N)``: every operation runs over contiguous
# rows of N numbers.


def _dot(a: Float, b: Float) -> float:
    return float(np.einsum("i,i->", a, b))


def _sq_norms(Q: Float) -> Float:
    """Squared lengths (N,) of the columns of Q (3, N)."""
    return Q[0] * Q[0] + Q[1] * Q[1] + Q[2] * Q[2]


def _gram(X: Float) -> Float:
    """``X Xᵀ`` for a few long rows X (k, N) by dot products of rows."""
    k = X.shape[0]
    G = np.empty((k, k))
    for i in range(k):
        for j in range(i, k):
            G[i, j] = G[j, i] = _dot(X[i], X[j])
    return G


def _algebraic(Q: Float) -> tuple[Float, float]:
    """Kasa's fit by normal equations (``Q`` (3, N) centred and scaled to unit RMS, so
    the 4x4 system is well conditioned)."""
    A = np.empty((4, Q.shape[1]))
    A[:3] = 2.0 * Q
    A[3] = 1.0
    rhs = _sq_norms(Q)
    sol = np.linalg.solve(_gram(A), np.array([_dot(a, rhs) for a in A]))
    c = sol[:3]
    r2 = sol[3] + c @ c
    return c, float(np.sqrt(max(r2, 0.0)))


def _normal(u: Float, r: Float, npar: int) -> tuple[Float, Float]:
    """``JᵀJ`` and ``Jᵀr`` for ``J = [-uᵀ, -1]`` (u the (3, N) unit directions) without
    forming ``J``."""
    JtJ = np.empty((npar, npar))
    JtJ[:3, :3] = _gram(u)
    g = np.empty(npar)
    g[:3] = [-_dot(u[k], r) for k in range(3)]
    if npar == 4:
        su = u.sum(axis=1)
        JtJ[:3, 3] = JtJ[3, :3] = su
        JtJ[3, 3] = u.shape[1]
        g[3] = -r.sum()
    return JtJ, g


def _columns(Q: Float, keep: np.ndarray) -> Float:
    """The points ``keep`` selects, with contiguous rows."""
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
    cost = _dot(r, r)
    mu = 1e-3
    it = 0
    JtJ, g = _normal(u, r, npar)
    for it in range(1, max_iter + 1):
        while True:
            try:
                step = -np.linalg.solve(JtJ + mu * np.diag(np.diag(JtJ)), g)
            except np.linalg.LinAlgError:
                step = np.full(npar, np.nan)
            x_new = x.copy()
            x_new[:npar] += step
            r_new, u_new = resid(x_new)
            cost_new = _dot(r_new, r_new)
            if cost_new <= cost:
                mu = max(mu / 10.0, 1e-12)
                break
            mu *= 10.0
            if mu > 1e12:
                return x[:3], float(x[3]), JtJ, it
        done = cost - cost_new <= 1e-12 * cost or float(np.linalg.norm(step)) <= 1e-7
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
                f"only {int(new.sum())} of {Q.shape[1]} points lie on one sphere; "
                f"expected at least {max(min_points, 4)}"
            )
        if np.array_equal(new, inl):
            break
        inl = new
    return c, R, JtJ, inl, iters, d


def _through_four(P4: Float) -> tuple[Float, Float, np.ndarray]:
    """Spheres (centres (K, 3), radii (K,)) through the 4 points of each ``P4`` (K, 4,
    3), and which of them are proper (the 4 points not close to one plane)."""
    A = np.concatenate([2.0 * P4, np.ones((*P4.shape[:2], 1))], axis=2)
    rhs = np.einsum("kij,kij->ki", P4, P4)
    # Coplanar samples: the tetrahedron's volume against the cube of its edges.
    e = P4[:, 1:] - P4[:, :1]
    vol = np.abs(np.linalg.det(e))
    size = np.max(np.einsum("kij,kij->ki", e, e), axis=1) ** 1.5
    ok = vol > 1e-6 * size
    A[~ok] = np.eye(4)
    sol = np.linalg.solve(A, rhs[..., None])[..., 0]
    c = sol[:, :3]
    r2 = sol[:, 3] + np.einsum("ki,ki->k", c, c)
    ok &= r2 > 0
    return c, np.sqrt(np.where(ok, r2, 1.0)), ok


def _ransac(
    Q: Float, fixed: float | None, band: float, rng: np.random.Generator
) -> tuple[Float, float, np.ndarray]:
    """The sphere with most points within ``band`` of its surface, among spheres
    through 4 random points (with a fixed radius ``fixed``: those within 10 % of it),
    scored on an even subset of the points; drawn until the best one would have been
    drawn with 99.9 % probability. Returns its centre, radius and the inliers (N,)."""
    N = Q.shape[1]
    stride = max(1, N // _SCORE_POINTS)
    S = np.ascontiguousarray(Q[:, ::stride])  # (3, n)
    s2 = _sq_norms(S)
    best_score, best_c, best_r = -1, np.zeros(3), 1.0
    drawn = 0
    need = _MAX_HYPOTHESES
    while drawn < min(need, _MAX_HYPOTHESES):
        idx = rng.integers(0, S.shape[1], size=(_BATCH, 4))
        drawn += _BATCH
        c, r, ok = _through_four(S.T[idx])
        if fixed is not None:
            ok &= np.abs(r - fixed) < 0.1 * fixed
            r = np.full_like(r, fixed)
        if not ok.any():
            continue
        c, r = c[ok], r[ok]
        # |s - c|² within ((r - band)², (r + band)²), without square roots
        d2 = s2[None, :] - 2.0 * (c[:, :1] * S[0] + c[:, 1:2] * S[1] + c[:, 2:3] * S[2])
        d2 += np.einsum("ki,ki->k", c, c)[:, None]
        lo = (np.clip(r - band, 0.0, None) ** 2)[:, None]
        hi = ((r + band) ** 2)[:, None]
        score = np.count_nonzero((d2 > lo) & (d2 < hi), axis=1)
        k = int(np.argmax(score))
        if score[k] > best_score:
            best_score, best_c, best_r = int(score[k]), c[k], float(r[k])
            miss = 1.0 - (best_score / S.shape[1]) ** 4
            need = int(np.ceil(np.log(1e-3) / np.log(miss))) if 0 < miss < 1 else 0
    inl = np.abs(_distances(Q, best_c)[0] - best_r) < band
    return best_c, best_r, inl


def _cap_half_angle(Q: Float, c: Float) -> float:
    """Largest angle [rad] at the centre ``c`` between the points' mean direction and a
    point of ``Q`` (3, N)."""
    dist, d = _distances(Q, c)
    u = d / np.maximum(dist, 1e-300)
    m = u.mean(axis=1)
    m /= max(float(np.linalg.norm(m)), 1e-300)
    cos = np.clip(np.einsum("i,in->n", m, u), -1.0, 1.0)
    return float(np.arccos(cos.min()))


def _spread(Q: Float) -> Float:
    """RMS extents (3,) of the points Q (3, N) along their principal axes, largest
    first (from the 3x3 scatter matrix)."""
    Qc = Q - Q.mean(axis=1, keepdims=True)
    ev = np.linalg.eigvalsh(_gram(Qc) / Q.shape[1])[::-1]
    return np.sqrt(np.clip(ev, 0.0, None))


def _check_shape(Q: Float) -> None:
    """Refuse clouds on a line or a plane (exactly: to 1e-7 of their extent, the
    resolution of the scatter matrix's eigenvalues)."""
    s = _spread(Q)
    if not s[0] > 1e-12 * float(np.abs(Q).max()):  # every point the same (to rounding)
        raise DataError(
            f"all {Q.shape[1]} points are the same point: a sphere is not determined; "
            "expected points spread over a sphere cap"
        )
    if s[1] <= 1e-7 * s[0]:
        raise DataError(
            "the points lie on a line: a sphere is not determined; expected points "
            "spread over a sphere cap"
        )
    if s[2] <= 1e-7 * s[0]:
        raise DataError(
            "the points lie on a plane (one circle lies on a plane): a sphere is not "
            "determined; expected points spread over a sphere cap, not in one plane"
        )


def fit_sphere(
    points: Float,
    *,
    radius: float | None = None,
    outlier_k: float | None = 4.0,
    segment: bool = True,
    max_rounds: int = 10,
    min_points: int = 10,
    seed: int = 0,
) -> SphereFit:
    """Fit a sphere to ``points`` (N, 3), segmented from what surrounds it.

    ``radius`` is the sphere's known radius: the centre alone is estimated. ``segment``
    runs the RANSAC segmentation (see the module notes) before the fit; ``outlier_k`` is
    the rejection threshold in robust standard deviations (``None``: keep every point,
    no segmentation). The covariance is ``s² (JᵀJ)⁻¹`` at the solution, ``s`` the RMS of
    the inliers corrected for the degrees of freedom. ``seed`` seeds the RANSAC draws
    (the result is the same for the same points and seed).

    Raises
    ------
    DataError
        Too few or non-finite points; points on a line or a plane (one circle); a cloud
        whose curvature does not stand out of its noise (no sphere is determined).
    """
    P, need = _checked_points(points, radius, min_points)
    Q = np.array(P.T, order="C")  # (3, N), contiguous rows
    origin = Q.mean(axis=1)
    Q -= origin[:, None]
    scale = float(np.sqrt(np.mean(_sq_norms(Q)))) or 1.0
    Q /= scale
    _check_shape(Q)
    fixed = None if radius is None else radius / scale
    # Large clouds: segmentation and the robust rounds first run on an evenly strided
    # subset of about 10k points; its sphere and noise level classify every point, and
    # the final rounds (which decide the result) use all points from there.
    stride = max(1, P.shape[0] // 10_000)
    Qs = np.ascontiguousarray(Q[:, ::stride])
    inl_s = np.ones(Qs.shape[1], bool)
    if segment and outlier_k is not None:
        # A band of 1 % of the cloud's size: far wider than the noise of a good scan,
        # far narrower than the gap to a support plate; the rounds below then narrow
        # (or widen) the inliers to k robust standard deviations.
        c, R, inl_s = _ransac(Qs, fixed, 0.01, np.random.default_rng(seed))
        if inl_s.sum() < need:
            c, R = _algebraic(Qs)
            inl_s = np.ones(Qs.shape[1], bool)
    else:
        c, R = _algebraic(Qs)
    if fixed is not None:
        R = fixed
    iters = 0
    inl = np.ones(P.shape[0], bool)
    if stride > 1:
        c, R, _, inl_s, it, _ = _rounds(
            Qs, c, R, fixed, outlier_k, max_rounds, min_points, inl_s
        )
        iters += it
        if outlier_k is not None:
            d = _distances(Q, c)[0] - R
            ds = d[::stride][inl_s]
            sig = 1.4826 * float(np.median(np.abs(ds - np.median(ds))))
            inl = np.abs(d) <= outlier_k * max(sig, 1e-12)
    else:
        inl = inl_s
    if inl.sum() < need:
        raise DataError(
            f"only {int(inl.sum())} of {P.shape[0]} points lie on one sphere; "
            f"expected at least {need}"
        )
    c, R, JtJ, inl, it, d = _rounds(
        Q, c, R, fixed, outlier_k, max_rounds, min_points, inl
    )
    iters += it
    npar = JtJ.shape[0]
    d_in = d[inl]
    n = int(inl.sum())
    rms = float(np.sqrt(np.mean(d_in**2)))
    s2 = _dot(d_in, d_in) / max(n - npar, 1)
    try:
        cov = np.linalg.inv(JtJ) * s2
    except np.linalg.LinAlgError:
        cov = np.full((npar, npar), np.inf)
    _check_curvature(Q[:, inl], rms, R, cov, scale)
    return SphereFit(
        center=c * scale + origin,
        radius=float(R * scale),
        rms=rms * scale,
        n=n,
        inliers=inl,
        covariance=np.asarray(cov * scale**2, dtype=float),
        iterations=iters,
        cap_half_angle=_cap_half_angle(Q[:, inl], c),
    )


def _checked_points(
    points: Float, radius: float | None, min_points: int
) -> tuple[Float, int]:
    """``(points (N, 3), the fewest points a fit needs)``, checked.

    Raises
    ------
    DataError
        Points not (N, 3), not finite, fewer than needed; a radius not positive.
    """
    P = np.asarray(points, dtype=float)
    if P.ndim != 2 or P.shape[1] != 3:
        raise DataError(f"points must be (N, 3), got {P.shape}")
    if not np.isfinite(P).all():
        bad = int(np.flatnonzero(~np.isfinite(P).all(axis=1))[0])
        raise DataError(f"point {bad} is not finite; expected finite x, y, z")
    need = max(min_points, 4)
    if P.shape[0] < need:
        raise DataError(f"{P.shape[0]} points; a sphere fit needs at least {need}")
    if radius is not None and not radius > 0:
        raise DataError(f"the radius must be positive, got {radius}")
    return P, need


def _check_curvature(Q: Float, rms: float, R: float, cov: Float, scale: float) -> None:
    """Refuse a fit whose inliers are flat within their noise: the best plane through
    them fits nearly as well as the sphere (RMS under 1.5x), or the centre's standard
    deviation exceeds the cloud's size."""
    s = _spread(Q)
    plane_rms, size = float(s[2]), float(s[0])
    std = (
        float(np.sqrt(np.max(np.diag(cov)[:3]))) if np.all(np.isfinite(cov)) else np.inf
    )
    if plane_rms <= 1.5 * rms or not std < size:
        raise DataError(
            "the points lie on a plane within their noise: a sphere is not determined "
            f"(best plane RMS {plane_rms * scale * 1e3:.4g} mm, sphere RMS "
            f"{rms * scale * 1e3:.4g} mm, radius {R * scale * 1e3:.4g} mm); expected "
            "a sphere cap whose curvature stands out of the noise"
        )
