"""From linked ridge points to the stripe's centres: the rules that keep or drop them.

Part of the ridge detector (:mod:`kinecal.sensor._ridge`, whose docstring states the
rules). Input: every ridge point of one image with its curve label; output: one centre
per cross-section with ``u, v, nx, ny, width, peak, flags``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from kinecal.sensor._ridge_link import one_per_section
from kinecal.typing import Float

__all__ = ["BORDER", "NEIGHBOUR", "RidgePoints", "select_centres"]

BORDER = 4  # within the filter's reach of the image border (the border was replicated)
NEIGHBOUR = 8  # another ridge (reflection) lost this cross-section close by

_FWHM = 2.0 * np.sqrt(2.0 * np.log(2.0))  # FWHM of a unit-sigma Gaussian
# Variance added to the stripe's own by pixel integration (1/12) and by the second
# difference standing for the second derivative (1/4, to first order): subtracted when
# the stripe's width is measured.
_EXTRA_VAR = 1.0 / 12.0 + 0.25


@dataclass(frozen=True)
class RidgePoints:
    """Ridge points of one image, each a candidate centre of one cross-section.

    Arrays (n,): ``x, y`` the pixel; ``u, v`` the centre [px]; ``nx, ny`` the unit
    normal; ``t`` the Newton step along it [px]; ``strength`` = -lambda [grey levels /
    px^2]; ``value`` the smoothed image at the pixel [grey levels]; ``offset`` the
    centre's distance from the pixel along its section [px]; ``steep`` whether the
    section is the pixel's row (else its column); ``label`` the curve; ``edges`` the
    links (pairs of indices).
    """

    x: np.ndarray
    y: np.ndarray
    u: Float
    v: Float
    nx: Float
    ny: Float
    t: Float
    strength: Float
    value: Float
    offset: Float
    steep: np.ndarray
    label: np.ndarray
    edges: tuple[np.ndarray, np.ndarray]


def select_centres(
    p: RidgePoints,
    img: np.ndarray,
    background: Callable[[Float, Float], Float],
    *,
    sigma: float,
    low: float,
    high: float,
    min_length: int,
    max_width: float,
) -> tuple[Float, np.ndarray, np.ndarray]:
    """Centres (K, 7), their curve's rank (0: strongest) and section type (row: True).

    ``low``, ``high``: hysteresis thresholds of the strength [grey levels / px^2];
    ``min_length``: fewest cross-sections of a curve; ``max_width``: widest FWHM [px].
    """
    H, W = img.shape
    keep = (np.abs(p.offset) <= 0.55) & (p.strength > low)
    # width and amplitude over the background: a Gaussian stripe of sigma s smoothed at
    # sigma gives r = A s / S and lambda = -A s / S^3 at its centre, S^2 = s^2 + sigma^2
    bg = background(p.u, p.v)
    lam = -p.strength
    r_c = p.value - 0.5 * lam * p.t * p.t - bg  # smoothed value at the centre (Taylor)
    S2 = -r_c / lam
    s2 = S2 - sigma * sigma - _EXTRA_VAR
    pos = s2 > 0.01
    width = np.where(pos, _FWHM * np.sqrt(np.where(pos, s2, 1.0)), 0.0)
    peak = np.where(pos, r_c * np.sqrt(np.abs(S2) / np.where(pos, s2, 1.0)), r_c)
    section = np.where(p.steep, p.y, H + p.x).astype(np.int64)
    position = np.where(p.steep, p.u, p.v)
    cos = np.abs(np.where(p.steep, p.nx, p.ny))
    lab = p.label
    m = int(lab.max()) + 1 if lab.size else 0
    alive = np.ones(m, bool)
    beside = np.zeros(lab.size, bool)  # won a section from a ridge close by
    for _ in range(3):  # curves that fail the rules leave; the others compete again
        cand = np.flatnonzero(keep & alive[lab])
        if cand.size == 0:
            return np.zeros((0, 7)), np.zeros(0, np.intp), np.zeros(0, bool)
        lc = lab[cand]
        score = np.bincount(lc, p.strength[cand], minlength=m)
        strongest = np.zeros(m)
        np.maximum.at(strongest, lc, p.strength[cand])
        kept, neighbour, (won, n_sec) = one_per_section(
            section[cand],
            lc,
            score[lc],
            p.offset[cand],
            position[cand],
            cos[cand],
            6 * sigma,
            m,
        )
        beside[cand[kept][neighbour]] = True
        lk = lc[kept]
        wide = np.bincount(lk, width[cand[kept]], minlength=m) / np.maximum(
            np.bincount(lk, minlength=m), 1
        )
        good = (
            (strongest >= high)
            & (n_sec >= min_length)
            & (won * 2 > n_sec)
            & (wide <= max_width)
        )
        if not np.any(alive & ~good):
            break
        alive &= good
    sel = cand[kept][good[lc[kept]]]
    neighbour = beside[sel]
    # Centres on unlit pixels go (the smoothing carries a ridge past the stripe's end):
    # the brighter of the two pixels a centre lies between must rise over the
    # background by 0.3 x the smoothed value at the centre.
    raw = _raw_at(img, p.u[sel], p.v[sel], p.steep[sel])
    ok = raw - bg[sel] >= 0.3 * r_c[sel]
    sel, neighbour = sel[ok], neighbour[ok]
    # So do the two last cross-sections at each end of a curve, where the end bends
    # the Hessian (not at the image border: there the stripe goes on).
    ok = ~_ends(section[sel], lab[sel] * 2 + p.steep[sel])
    at_border = (p.u < 2.5) | (p.v < 2.5) | (p.u > W - 3.5) | (p.v > H - 3.5)
    ok |= at_border[sel]
    sel, neighbour = sel[ok], neighbour[ok]
    u, v = p.u[sel], p.v[sel]
    reach = int(np.ceil(3.0 * sigma)) + 1
    border = (u < reach) | (v < reach) | (u > W - 1 - reach) | (v > H - 1 - reach)
    flags = np.where(neighbour, NEIGHBOUR, 0) | np.where(border, BORDER, 0)
    out = np.stack(
        [u, v, p.nx[sel], p.ny[sel], width[sel], peak[sel], flags.astype(float)], axis=1
    )
    rank = np.argsort(np.argsort(-score))[lab[sel]]
    order = np.lexsort((u, v, rank))
    return out[order], rank[order], p.steep[sel][order]


def _raw_at(img: np.ndarray, u: Float, v: Float, steep: np.ndarray) -> Float:
    """The brighter raw pixel of the two a centre lies between along its section."""
    H, W = img.shape
    ui = np.clip(np.rint(u).astype(np.intp), 0, W - 1)
    vi = np.clip(np.rint(v).astype(np.intp), 0, H - 1)
    a = np.floor(np.where(steep, u, v)).astype(np.intp)
    lim = np.where(steep, W - 1, H - 1)
    b = np.clip(a + 1, 0, lim)
    a = np.clip(a, 0, lim)
    first = np.where(
        steep, img[vi, np.minimum(a, W - 1)], img[np.minimum(a, H - 1), ui]
    )
    second = np.where(
        steep, img[vi, np.minimum(b, W - 1)], img[np.minimum(b, H - 1), ui]
    )
    return np.maximum(first, second).astype(float)


def _ends(section: np.ndarray, group: np.ndarray) -> np.ndarray:
    """Points within two sections of the first or last section of their group."""
    n = int(group.max()) + 1 if group.size else 0
    lo = np.full(n, np.iinfo(np.int64).max)
    hi = np.full(n, np.iinfo(np.int64).min)
    np.minimum.at(lo, group, section)
    np.maximum.at(hi, group, section)
    return (section <= lo[group] + 1) | (section >= hi[group] - 1)
