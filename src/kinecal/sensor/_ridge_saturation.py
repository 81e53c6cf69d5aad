"""Saturated stripe centres: a Gaussian fitted to the unsaturated flanks of the profile.

Part of the ridge detector (:mod:`kinecal.sensor._ridge`). Where the profile across a
centre is clipped, its flat top says nothing about the centre; the flanks still follow
the stripe's Gaussian ``A exp(-(x - x0)^2 / 2 s^2)``, whose logarithm is the parabola

.. math::

    \\ln y = a + b x + c x^2, \\qquad x_0 = -\\frac{b}{2c}, \\quad
    s = \\sqrt{-\\frac{1}{2c}}, \\quad A = e^{a - b^2 / 4c}

fitted by least squares with weights ``y^2`` (the variance of ``ln y`` is
``sigma_noise^2 / y^2``) to the background-subtracted samples along the normal that
are neither clipped nor interpolated from a clipped pixel (three lines, one pixel apart
along the stripe, against speckle). ``x`` is the distance along the normal from the
ridge centre [px], ``y`` the sample over the background [grey levels]. The
interpolation flattens a narrow stripe's profile: the fitted amplitude and width are
those of the interpolated profile (for a stripe of sigma 1.6 px the amplitude comes out
about a quarter low), the centre is not moved by it (the profile stays symmetric).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kinecal.typing import Float

__all__ = ["FIT_FAILED", "SATURATED", "fit_flanks"]

SATURATED = 1  # clipped profile: centre from a Gaussian fit to the unsaturated flanks
FIT_FAILED = 2  # clipped profile whose flanks do not determine a fit: ridge centre kept
_FWHM = 2.0 * np.sqrt(2.0 * np.log(2.0))


def fit_flanks(
    img: np.ndarray,
    pts: Float,
    steep: np.ndarray,
    saturation: float,
    background: Callable[[Float, Float], Float],
    sigma: float,
    noise: float,
) -> None:
    """Find the centres of ``pts`` (K, 7) whose profile is clipped and refit them.

    ``pts`` columns ``u, v, nx, ny, width, peak, flags`` are updated in place:
    saturated centres move along their row (``steep``) or column to the fitted peak,
    get the fitted FWHM and amplitude and the flag ``SATURATED``, or ``FIT_FAILED``
    (centre kept) when the flanks do not determine the fit.
    """
    H, W = img.shape
    if float(img.max()) < saturation:
        return
    u, v, nx, ny = pts[:, 0], pts[:, 1], pts[:, 2], pts[:, 3]
    j = np.arange(-3, 4)
    uu = np.clip(np.rint(u[:, None] + j * nx[:, None]).astype(np.intp), 0, W - 1)
    vv = np.clip(np.rint(v[:, None] + j * ny[:, None]).astype(np.intp), 0, H - 1)
    # A plateau: two clipped pixels or more across the stripe (one pixel clipped by a
    # speckle grain does not move the ridge centre).
    hit = np.flatnonzero(np.count_nonzero(img[vv, uu] >= saturation, axis=1) >= 2)
    if hit.size == 0:
        return
    reach = 3.0 * sigma + 4.0  # the flanks of a plateau up to 8 px wide
    x = np.arange(-np.ceil(reach), np.ceil(reach) + 1.0)
    m = np.array([-1.0, 0.0, 1.0])
    K, X, M = hit.size, x.size, m.size
    n_x, n_y = nx[hit, None, None], ny[hit, None, None]
    su = u[hit, None, None] + x[None, :, None] * n_x - m[None, None, :] * n_y
    sv = v[hit, None, None] + x[None, :, None] * n_y + m[None, None, :] * n_x
    val, clipped = _bilinear(img, su, sv, saturation)
    y = val - background(u[hit], v[hit])[:, None, None]  # smooth: one value per centre
    xs = np.broadcast_to(x[None, :, None], (K, X, M))
    good = ~clipped & (y > 3.0 * noise) & (su >= 0) & (su <= W - 1)
    good &= (sv >= 0) & (sv <= H - 1)
    w = np.where(good, y * y, 0.0)
    ly = np.log(np.where(good, y, 1.0))
    p = [np.ones_like(xs), xs, xs * xs]
    A = np.empty((K, 3, 3))
    rhs = np.empty((K, 3))
    for a in range(3):
        rhs[:, a] = np.sum(w * p[a] * ly, axis=(1, 2))
        for b in range(a, 3):
            A[:, a, b] = A[:, b, a] = np.sum(w * p[a] * p[b], axis=(1, 2))
    left = np.sum(good & (xs < 0), axis=(1, 2))
    right = np.sum(good & (xs > 0), axis=(1, 2))
    det = np.linalg.det(A)
    ok = (left >= 3) & (right >= 3) & (np.abs(det) > 1e-12 * np.abs(A[:, 0, 0]) ** 3)
    coef = np.zeros((K, 3))
    if ok.any():
        coef[ok] = np.linalg.solve(A[ok], rhs[ok][:, :, None])[:, :, 0]
    a0, b1, c2 = coef[:, 0], coef[:, 1], coef[:, 2]
    ok &= c2 < 0
    with np.errstate(divide="ignore", invalid="ignore"):
        x0 = np.where(ok, -b1 / (2.0 * c2), 0.0)
        s = np.sqrt(np.where(ok, -0.5 / c2, 1.0))
        amp = np.exp(np.where(ok, a0 - b1 * b1 / (4.0 * c2), 0.0))
    ok &= np.abs(x0) <= 2.0
    flags = pts[hit, 6].astype(np.int64)
    st = steep[hit]
    g = hit[ok]
    shift = np.where(st[ok], x0[ok] / nx[g], x0[ok] / ny[g])
    pts[g, 0] += np.where(st[ok], shift, 0.0)
    pts[g, 1] += np.where(st[ok], 0.0, shift)
    pts[g, 4] = _FWHM * s[ok]
    pts[g, 5] = amp[ok]
    pts[hit, 6] = (flags | np.where(ok, SATURATED, FIT_FAILED)).astype(float)


def _bilinear(
    img: np.ndarray, u: Float, v: Float, saturation: float
) -> tuple[Float, np.ndarray]:
    """Bilinear samples of ``img`` at ``u, v``, and whether any pixel used is clipped."""
    H, W = img.shape
    uc = np.clip(u, 0.0, W - 1.0)
    vc = np.clip(v, 0.0, H - 1.0)
    x0 = np.minimum(uc.astype(np.intp), W - 2)
    y0 = np.minimum(vc.astype(np.intp), H - 2)
    fx, fy = uc - x0, vc - y0
    p00 = img[y0, x0].astype(float)
    p01 = img[y0, x0 + 1].astype(float)
    p10 = img[y0 + 1, x0].astype(float)
    p11 = img[y0 + 1, x0 + 1].astype(float)
    val = (p00 * (1 - fx) + p01 * fx) * (1 - fy) + (p10 * (1 - fx) + p11 * fx) * fy
    clipped = np.maximum(np.maximum(p00, p01), np.maximum(p10, p11)) >= saturation
    return val, clipped
