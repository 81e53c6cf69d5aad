"""Laser-stripe centres in any direction: a Hessian ridge detector (Steger's method).

A stripe is a bright ridge of the image smoothed by a Gaussian of scale ``sigma``
(1.5 px, matched to the stripe when it is wider). At a pixel ``p`` the Hessian of the
smoothed image ``r`` has its most negative eigenvalue ``lambda`` across the stripe,
with unit eigenvector ``n`` (the normal); the second-order Taylor polynomial of ``r``
along ``n`` peaks at

.. math::

    p + t\\,n, \\qquad
    t = -\\frac{r_x n_x + r_y n_y}{r_{xx} n_x^2 + 2 r_{xy} n_x n_y + r_{yy} n_y^2}
      = -\\frac{\\nabla r \\cdot n}{\\lambda}

(Steger 1998, Sec. 3: the line point of a 2-D line); ``-lambda`` is the ridge
strength. Symbols: ``r_x, r_y`` and ``r_xx, r_xy, r_yy`` the first and second
derivatives of ``r`` (central differences of the smoothed image) [grey levels / px,
/ px^2]. One centre per cross-section: where the
stripe runs steeper than 45 deg the local line through ``p + t n`` is cut with the
pixel's row, ``u = x + t / n_x`` (kept if ``|t / n_x| <= 0.5``: each row has one such
pixel), elsewhere with its column, ``v = y + t / n_y``; which of the two is decided on
the normals averaged along the curve, so that a stripe near 45 deg does not switch at
every pixel.

Speed: a stripe is a thin band. A coarse pass (the image averaged over 4 x 4 blocks, its
second differences by 3 x 3 Sobel kernels) marks the 16 x 16 tiles the stripe may cross;
only those tiles, padded by the filter's reach, are smoothed (one OpenCV call on a strip
of tiles) and searched, and only pixels whose second differences pass the low threshold
get the full Hessian. A line is darker on both sides: 1.5 sigma away along the normal the
smoothed image must drop by a quarter of what the ridge's curvature predicts, on each
side (an edge's shoulder curves down too, but does not drop on one side).

Curvature: the smoothing pulls the ridge of a curved stripe towards its centre of
curvature by ``sigma^2 kappa / 2`` (a ring of radius ``R`` smoothed by a Gaussian peaks
at ``R - sigma^2 / 2R``); ``kappa`` is measured from the turn of the normals along the
linked curve (:func:`~kinecal.sensor._ridge_link.curvature`, averaged over four rounds
of neighbours) and the centre is moved back.

Linking, primary stripe, false centres: accepted points are linked into curves (within
two pixels, normals within 30 deg) and kept by hysteresis (every point's strength above
``low`` noise levels, each curve's strongest above ``high``) and length (``min_length``
cross-sections). Where centres of several curves fall in one cross-section (a reflection
or a second stripe beside the primary one), the curve with the largest summed strength
wins (strength x length: a long, strong, continuous stripe beats short, weak or broken
ones); a curve that loses half of its cross-sections or more is a reflection and is
dropped whole; curves wider than ``max_width_px`` (glare) are dropped too. The winner is
flagged ``NEIGHBOUR`` when the loser was within six filter scales of it. Centres on
unlit pixels (past a stripe's end, where the smoothing carries the ridge on) and the last
two cross-sections at each end of a curve (the end bends the Hessian) are dropped, not
at the image border, where the stripe goes on.

Background: a grey opening (40 px) of the image averaged over 8 x 8 blocks, blurred, is
the background; it is subtracted from the smoothed value before the stripe's width and
amplitude are measured, and from the profiles fitted under saturation. Saturation: where
two raw pixels or more across a centre are at the saturation level, the centre moves
to the peak of a Gaussian fitted (weighted log-parabola) to the unsaturated flank
samples along the normal and is flagged ``SATURATED`` (``FIT_FAILED`` when the flanks do
not determine it; the ridge centre is kept).

References: C. Steger, "An unbiased detector of curvilinear structures", IEEE TPAMI
20(2), 1998, 113-125 (the centre and the strength; the linking here is a vectorised
variant of the idea, not the paper's sequential algorithm).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from kinecal.errors import ConfigError
from kinecal.sensor._cv import require_cv2
from kinecal.sensor._ridge_link import (
    components,
    curvature,
    link_edges,
    smooth_over_edges,
)
from kinecal.sensor._ridge_saturation import FIT_FAILED, SATURATED, fit_flanks
from kinecal.sensor._ridge_select import (
    BORDER,
    NEIGHBOUR,
    RidgePoints,
    select_centres,
)
from kinecal.typing import Float

__all__ = [
    "BORDER",
    "FIT_FAILED",
    "NEIGHBOUR",
    "SATURATED",
    "RidgeOptions",
    "ridge_centres",
]

_TILE = 16  # tile side [px]
_COARSE = 4  # coarse block side [px]
_FWHM = 2.0 * np.sqrt(2.0 * np.log(2.0))  # FWHM of a unit-sigma Gaussian
_FIRST_SIGMA = 1.5  # [px] first pass of the automatic scale


@dataclass(frozen=True)
class RidgeOptions:
    """Options of :func:`ridge_centres` (lengths in pixels).

    ``sigma_px``: the smoothing scale; None matches it to the stripe: a first pass at
    1.5 px measures the stripe's Gaussian width ``s`` (median over its centres) and,
    if ``s`` is over 2.4 px, the tiles are searched again at ``s`` (at most 8 px).
    Narrower stripes keep 1.5 px: averaging over more pixels along the stripe makes
    their centres less noisy under speckle (measured: 0.05 against 0.09 px RMS for a
    stripe of 0.6 px at 0.8 px). ``low``, ``high``: hysteresis thresholds of the ridge
    strength in noise levels (the noise is measured on the image). ``min_length``:
    fewest cross-sections of a kept curve. ``max_width_px``: widest stripe (FWHM) kept;
    None: 4 x the FWHM of a stripe matched to ``sigma``. ``saturation``: grey level of
    a clipped pixel; None: the largest value of the image's type (255, 65535).
    """

    sigma_px: float | None = None
    low: float = 3.0
    high: float = 8.0
    min_length: int = 8
    max_width_px: float | None = None
    saturation: float | None = None

    def __post_init__(self) -> None:
        if self.sigma_px is not None and not 0.5 <= self.sigma_px <= 10.0:
            raise ConfigError(
                f"sigma_px must be within 0.5..10 px, got {self.sigma_px}"
            )
        if not 0 < self.low <= self.high:
            raise ConfigError(
                f"thresholds must satisfy 0 < low <= high, got low={self.low}, "
                f"high={self.high}"
            )
        if self.min_length < 1:
            raise ConfigError(f"min_length must be >= 1, got {self.min_length}")
        if self.max_width_px is not None and self.max_width_px <= 0:
            raise ConfigError(f"max_width_px must be positive, got {self.max_width_px}")


def ridge_centres(image: np.ndarray, options: RidgeOptions | None = None) -> Float:
    """Stripe centres (K, 7) of a grey image (H, W): ``u, v, nx, ny, width, peak, flags``.

    ``u, v`` [px], pixel-centre convention; ``nx, ny`` the unit normal across the stripe
    (towards +u where the stripe is steep, +v where it is flat); ``width`` its FWHM [px]
    (0 where not measurable); ``peak`` its amplitude above the background [grey levels];
    ``flags`` the sum of the flag bits (:data:`SATURATED` 1, :data:`FIT_FAILED` 2,
    :data:`BORDER` 4, :data:`NEIGHBOUR` 8). Rows go by curve (strongest first), then
    by row and column.
    """
    opt = options or RidgeOptions()
    cv2 = require_cv2("stripe extraction")
    pre = _Image.of(np.asarray(image), opt, cv2)
    sigma = _FIRST_SIGMA if opt.sigma_px is None else float(opt.sigma_px)
    loose = opt.max_width_px or 4.0 * _FWHM * 8.0  # any stripe the scale can match
    pts, curve, steep = _centres(pre, sigma, opt, cv2, loose)
    if opt.sigma_px is None and pts.shape[0]:
        s = _median(pts[:, 4]) / _FWHM
        if s > 1.6 * sigma:  # a wide stripe: match the scale to it
            sigma = float(min(s, 8.0))
            pts, curve, steep = _centres(pre, sigma, opt, cv2, loose)
    # glare: curves wider than max_width_px on average
    max_w = opt.max_width_px or 4.0 * _FWHM * sigma
    if pts.shape[0]:
        n = np.maximum(np.bincount(curve), 1)
        keep = ~(np.bincount(curve, pts[:, 4]) / n > max_w)[curve]
        pts, steep = pts[keep], steep[keep]
    if pts.shape[0] and np.isfinite(pre.saturation):
        fit_flanks(
            pre.img, pts, steep, pre.saturation, pre.background, sigma, pre.noise
        )
    return pts


@dataclass
class _Image:
    """What every pass over one image shares: the image, its noise, its background."""

    img: np.ndarray
    noise: float  # [grey levels] of a pixel
    coarse: np.ndarray  # (h, w) float32, the image averaged over 4 x 4 blocks
    bg: np.ndarray  # (h / 2, w / 2) float32, the background over 8 x 8 blocks
    saturation: float

    @classmethod
    def of(cls, img: np.ndarray, opt: RidgeOptions, cv2: Any) -> _Image:
        H, W = img.shape
        half = cv2.resize(
            img, (max(W // 2, 1), max(H // 2, 1)), interpolation=cv2.INTER_AREA
        )
        coarse = cv2.resize(
            half.astype(np.float32),
            (max(W // _COARSE, 1), max(H // _COARSE, 1)),
            interpolation=cv2.INTER_AREA,
        )
        # Read noise: differences of neighbouring pixels of a sparse sample, winsorised
        # (the few stripe pixels in it do not count).
        d = np.diff(img[::64, :: max(W // 320, 1)].astype(np.float32), axis=1).ravel()
        clip = max(4.5 * _median(np.abs(d)), 3.0)
        noise = float(np.sqrt(np.mean(np.minimum(d * d, clip * clip)) / 2.0))
        # Background: grey opening of the image averaged over 8 x 8 blocks, 5 blocks
        # wide (40 px; a stripe is narrower and disappears), blurred.
        h8, w8 = max(H // 8, 1), max(W // 8, 1)
        bg = cv2.resize(coarse, (w8, h8), interpolation=cv2.INTER_AREA)
        bg = cv2.morphologyEx(bg, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
        bg = cv2.blur(bg, (3, 3))
        if opt.saturation is not None:
            sat = float(opt.saturation)
        elif np.issubdtype(img.dtype, np.integer):
            sat = float(np.iinfo(img.dtype).max)
        else:
            sat = np.inf
        return cls(img, max(noise, 0.5), coarse, bg, sat)

    def background(self, u: Float, v: Float) -> Float:
        """Background [grey levels] at pixels ``u, v`` (bilinear in the coarse map)."""
        h, w = self.bg.shape
        H, W = self.img.shape
        x = np.clip((u + 0.5) * (w / W) - 0.5, 0.0, w - 1.0)
        y = np.clip((v + 0.5) * (h / H) - 0.5, 0.0, h - 1.0)
        return np.asarray(_bilinear(self.bg, x, y), float)


def _kernel(sigma: float) -> tuple[np.ndarray, int]:
    """A sampled Gaussian of ``sigma`` [px] (float32, sum 1) and its radius (3 sigma)."""
    R = int(np.ceil(3.0 * sigma))
    x = np.arange(-R, R + 1)
    g = np.exp(-0.5 * (x / sigma) ** 2)
    return (g / g.sum()).astype(np.float32), R


def _tiles(pre: _Image, cv2: Any) -> tuple[np.ndarray, np.ndarray]:
    """Tile rows and columns (N,) the stripe may cross, from the coarse image.

    Coarse pixels whose smaller second difference along u or v (at most half the most
    negative eigenvalue on a ridge of any direction) is 4 noise levels below zero (the
    noise measured on the coarse image: a robust spread), and their neighbours, mark
    their tiles.
    """
    H, W = pre.img.shape
    nty, ntx = -(-H // _TILE), -(-W // _TILE)
    if min(pre.coarse.shape) < 16:  # a small image (under 64 px): search it all
        ty, tx = np.nonzero(np.ones((nty, ntx), bool))
        return ty, tx
    # second differences, smoothed across by [1, 2, 1] (Sobel's 3 x 3 kernels)
    gxx = cv2.Sobel(pre.coarse, -1, 2, 0, ksize=3, borderType=cv2.BORDER_REPLICATE)
    gyy = cv2.Sobel(pre.coarse, -1, 0, 2, ksize=3, borderType=cv2.BORDER_REPLICATE)
    noise = 1.4826 * _median(np.abs(gxx[::6, ::6]))  # gxx has zero mean
    cand = (np.minimum(gxx, gyy) < -4.0 * max(noise, 1e-3)).view(np.uint8)
    # A tile (4 x 4 coarse pixels) is searched if a candidate is in it or next to it:
    # a 6 x 6 dilation anchored one pixel up and left, sampled at every tile's corner.
    per = _TILE // _COARSE
    near = cv2.dilate(cand, np.ones((per + 2, per + 2), np.uint8), anchor=(1, 1))
    ty, tx = np.nonzero(near[::per, ::per][:nty, :ntx])
    return ty, tx


def _centres(
    pre: _Image, sigma: float, opt: RidgeOptions, cv2: Any, max_w: float
) -> tuple[Float, np.ndarray, np.ndarray]:
    """One pass at scale ``sigma``: centres (K, 7), their curve's rank, their type.

    Before the saturation fit; the type is True for a row cross-section (steep stripe).
    """
    kg, _ = _kernel(sigma)
    k2 = np.convolve(kg, [1.0, -2.0, 1.0])
    # noise of a second difference of the smoothed image (white noise of the pixels)
    s_lam = pre.noise * float(np.linalg.norm(k2) * np.linalg.norm(kg))
    pts = _points(pre, sigma, opt.low * s_lam, cv2)
    if pts is None:
        return np.zeros((0, 7)), np.zeros(0, np.intp), np.zeros(0, bool)
    return select_centres(
        pts,
        pre.img,
        pre.background,
        sigma=sigma,
        low=opt.low * s_lam,
        high=opt.high * s_lam,
        min_length=opt.min_length,
        max_width=max_w,
    )


def _smoothed_strip(
    img: np.ndarray, ty: np.ndarray, tx: np.ndarray, sigma: float, cv2: Any
) -> tuple[np.ndarray, int]:
    """``(the N tiles with a border of P pixels side by side (T2, N * T2), smoothed at
    scale sigma; P)``, ``T2 = _TILE + 2 P``."""
    H, W = img.shape
    N = ty.size
    kg, R = _kernel(sigma)
    P = R + 1
    T2 = _TILE + 2 * P
    nty, ntx = -(-H // _TILE), -(-W // _TILE)
    pad = cv2.copyMakeBorder(
        img, P, nty * _TILE - H + P, P, ntx * _TILE - W + P, cv2.BORDER_REPLICATE
    )
    s0, s1 = pad.strides
    view = np.lib.stride_tricks.as_strided(
        pad, (nty, ntx, T2, T2), (_TILE * s0, _TILE * s1, s0, s1), writeable=False
    )
    # Tiles side by side in one strip (T2, N * T2): one smoothing call for all.
    strip = view[ty, tx].transpose(1, 0, 2).reshape(T2, N * T2)
    r = cv2.sepFilter2D(strip, cv2.CV_32F, kg, kg, borderType=cv2.BORDER_REPLICATE)
    return r, P


def _points(pre: _Image, sigma: float, low: float, cv2: Any) -> RidgePoints | None:
    """Ridge points of the tiles at scale ``sigma``, linked into curves."""
    H, W = pre.img.shape
    ty, tx = _tiles(pre, cv2)
    N = ty.size
    if N == 0:
        return None
    r, P = _smoothed_strip(pre.img, ty, tx, sigma, cv2)
    T2 = _TILE + 2 * P
    # The interiors and a one-pixel ring, contiguous: (T + 2, N * (T + 2)). Differences
    # along a row cross from tile to tile only at the ring columns, not searched.
    T1 = _TILE + 2
    rr = r.reshape(T2, N, T2)[P - 1 : P + _TILE + 1, :, P - 1 : P + _TILE + 1]
    rr = np.ascontiguousarray(rr).reshape(T1, N * T1)
    c = rr[1:-1, 1:-1]
    e, w_ = rr[1:-1, 2:], rr[1:-1, :-2]
    s_, n_ = rr[2:, 1:-1], rr[:-2, 1:-1]
    hxx = e + w_ - (c + c)
    hyy = s_ + n_ - (c + c)
    gx2, gy2 = e - w_, s_ - n_  # twice the first differences
    # Candidates: the trace (about lambda on a line) below the low threshold and the
    # pixel near the crossing of its row or column (1-D Newton step under 0.75 px).
    cand = (hxx + hyy < -0.9 * low) & (
        (np.abs(gx2) <= 1.5 * np.abs(hxx)) | (np.abs(gy2) <= 1.5 * np.abs(hyy))
    )
    cand[:, _TILE::T1] = False  # the ring columns between tiles
    cand[:, _TILE + 1 :: T1] = False
    flat = np.flatnonzero(cand)
    L = N * T1 - 2
    iy, jx = np.divmod(flat, L)
    it, ix = np.divmod(jx, T1)
    f = (iy + 1) * (N * T1) + jx + 1  # flat index in rr
    rf = rr.reshape(-1)
    row = N * T1
    hxx, hyy = hxx.reshape(-1)[flat], hyy.reshape(-1)[flat]
    gx, gy = 0.5 * gx2.reshape(-1)[flat], 0.5 * gy2.reshape(-1)[flat]
    hxy = 0.25 * (rf[f + row + 1] - rf[f + row - 1] - rf[f - row + 1] + rf[f - row - 1])
    dd = 0.5 * (hxx - hyy)
    disc = np.sqrt(dd * dd + hxy * hxy)
    lam = 0.5 * (hxx + hyy) - disc  # the most negative eigenvalue
    x = tx[it] * _TILE + ix
    y = ty[it] * _TILE + iy
    # a bright line: the eigenvalue of largest magnitude is the negative one
    k = np.flatnonzero((lam < -low) & (hxx + hyy < 0) & (x < W) & (y < H))
    dd, hxy, disc, lam = dd[k], hxy[k], disc[k], lam[k]
    # its eigenvector: two equivalent forms, the better conditioned one
    first = dd >= 0
    nx = np.where(first, hxy, disc - dd)
    ny = np.where(first, -(dd + disc), -hxy)
    norm = np.hypot(nx, ny)
    norm[norm == 0] = 1.0
    nx, ny = nx / norm, ny / norm
    t = -(gx[k] * nx + gy[k] * ny) / lam  # Steger (1998): the Newton step
    x, y, c0 = x[k], y[k], rf[f[k]]
    with np.errstate(divide="ignore", invalid="ignore"):
        off_row = t / nx  # along the row to where the line crosses it
        off_col = t / ny  # along the column
    take = (np.abs(off_row) <= 0.55) | (np.abs(off_col) <= 0.55)
    # A line is darker on both sides: 1.5 sigma away along the normal the smoothed
    # image must have dropped by a quarter of what its curvature predicts, on each
    # side (the shoulder of an edge curves down too, but one side does not drop).
    D = 1.5 * sigma
    yl = (iy[k] + P).astype(np.float32)
    xl = (it[k] * T2 + ix[k] + P).astype(np.float32)
    r2 = r.reshape(T2, N * T2)
    top = c0 + 0.125 * lam * D * D
    for sgn in (-1.0, 1.0):
        take &= _bilinear(r2, xl + sgn * D * nx, yl + sgn * D * ny) <= top
    q = np.flatnonzero(take)
    x, y, nx, ny, t, lam, c0 = (a[q] for a in (x, y, nx, ny, t, lam, c0))
    ei, ej = link_edges(x, y, nx, ny, W)
    # Row or column per point, from cos(2 angle) of the normal averaged along the curve;
    # the normal turned towards +u (rows) or +v (columns).
    steep = smooth_over_edges(nx * nx - ny * ny, ei, ej, 3) >= 0
    sgn = np.where(steep, np.sign(nx), np.sign(ny))
    sgn[sgn == 0] = 1.0
    nx, ny, t = nx * sgn, ny * sgn, t * sgn
    # The smoothing pulls the ridge of a curved stripe towards its centre of curvature
    # by sigma^2 kappa / 2 (a ring smoothed by a Gaussian peaks at r - sigma^2 / 2r):
    # moved back, with the curvature averaged along the curve.
    kx, ky = curvature(x + t * nx, y + t * ny, nx, ny, ei, ej)
    bend = smooth_over_edges(kx * nx + ky * ny, ei, ej, 4)  # kappa along n [1/px]
    t = t - 0.5 * sigma * sigma * np.clip(bend, -0.1, 0.1)
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(steep, t / nx, t / ny)  # to the row's or column's crossing
    return RidgePoints(
        x=x,
        y=y,
        u=x + np.where(steep, off, 0.0),
        v=y + np.where(steep, 0.0, off),
        nx=nx,
        ny=ny,
        t=t,
        strength=-lam,
        value=c0,
        offset=off,
        steep=steep,
        label=components(x.size, ei, ej),
        edges=(ei, ej),
    )


def _median(a: np.ndarray) -> float:
    """``float(np.median(a))`` of an array without NaN, the same bits (the two middle
    values averaged by np.mean in the array's type), without the import of
    ``numpy.ma`` that np.median makes on its first call (~10 ms of a command)."""
    v = np.ravel(a)
    h = v.size // 2
    if v.size % 2:
        return float(np.partition(v, h)[h])
    return float(np.mean(np.partition(v, [h - 1, h])[h - 1 : h + 1]))


def _bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear samples of ``img`` (H, W) at ``x, y`` (inside it)."""
    x0 = np.minimum(x.astype(np.intp), img.shape[1] - 2)
    y0 = np.minimum(y.astype(np.intp), img.shape[0] - 2)
    fx, fy = x - x0, y - y0
    top = img[y0, x0] * (1 - fx) + img[y0, x0 + 1] * fx
    bot = img[y0 + 1, x0] * (1 - fx) + img[y0 + 1, x0 + 1] * fx
    return np.asarray(top * (1 - fy) + bot * fy)
