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
    none = np.zeros((0, 7)), np.zeros(0, np.intp), np.zeros(0, bool)
    lab = p.label
    m = int(lab.max()) + 1 if lab.size else 0
    # Points near their section's crossing and above the low threshold, of curves
    # long and strong enough (hysteresis): all the others leave at once.
    q = np.flatnonzero((np.abs(p.offset) <= 0.55) & (p.strength > low))
    strong = np.bincount(lab[q], p.strength[q] >= high, minlength=m) > 0
    alive = (np.bincount(lab[q], minlength=m) >= min_length) & strong
    q = q[alive[lab[q]]]
    if q.size == 0:
        return none
    lq, st, steep = lab[q], p.strength[q], p.steep[q]
    u, v = p.u[q], p.v[q]
    # width and amplitude over the background: a Gaussian stripe of sigma s smoothed at
    # sigma gives r = A s / S and lambda = -A s / S^3 at its centre, S^2 = s^2 + sigma^2
    bg = background(u, v)
    r_c = p.value[q] + 0.5 * st * p.t[q] ** 2 - bg  # smoothed value at the centre
    S2 = r_c / st
    s2 = S2 - sigma * sigma - _EXTRA_VAR
    pos = s2 > 0.01
    width = np.where(pos, _FWHM * np.sqrt(np.where(pos, s2, 1.0)), 0.0)
    section = np.where(steep, p.y[q], H + p.x[q]).astype(np.int64)
    position = np.where(steep, u, v)
    cos = np.abs(np.where(steep, p.nx[q], p.ny[q]))
    offset = p.offset[q]
    score = np.bincount(lq, st, minlength=m)  # summed strength: strength x length
    live = np.ones(q.size, bool)
    beside = np.zeros(q.size, bool)  # won a section from a ridge close by
    for _ in range(3):  # curves that fail the rules leave; the others compete again
        c = np.flatnonzero(live)
        if c.size == 0:
            return none
        lc = lq[c]
        kept, neighbour, (won, n_sec) = one_per_section(
            section[c], lc, score[lc], offset[c], position[c], cos[c], 6 * sigma, m
        )
        beside[c[kept][neighbour]] = True
        lk = lc[kept]
        wide = np.bincount(lk, width[c[kept]], minlength=m) / np.maximum(
            np.bincount(lk, minlength=m), 1
        )
        good = (n_sec >= min_length) & (won * 2 > n_sec) & (wide <= max_width)
        if not np.any(alive & ~good):
            break
        alive &= good
        live &= good[lq]
    sel = c[kept][good[lc[kept]]]
    # Centres on unlit pixels go (the smoothing carries a ridge past the stripe's end):
    # the brighter of the two pixels a centre lies between must rise over the
    # background by 0.3 x the smoothed value at the centre.
    raw = _raw_at(img, u[sel], v[sel], steep[sel])
    sel = sel[raw - bg[sel] >= 0.3 * r_c[sel]]
    # So do the two last cross-sections at each end of a curve, where the end bends
    # the Hessian (not at the image border: there the stripe goes on).
    us, vs = u[sel], v[sel]
    at_border = (us < 2.5) | (vs < 2.5) | (us > W - 3.5) | (vs > H - 3.5)
    sel = sel[~_ends(section[sel], lq[sel] * 2 + steep[sel]) | at_border]
    us, vs = u[sel], v[sel]
    reach = int(np.ceil(3.0 * sigma)) + 1
    border = (us < reach) | (vs < reach) | (us > W - 1 - reach) | (vs > H - 1 - reach)
    flags = np.where(beside[sel], NEIGHBOUR, 0) | np.where(border, BORDER, 0)
    r_s, S2_s, s2_s = r_c[sel], S2[sel], s2[sel]
    ok = pos[sel]
    peak = np.where(ok, r_s * np.sqrt(np.abs(S2_s) / np.where(ok, s2_s, 1.0)), r_s)
    nx, ny = p.nx[q][sel], p.ny[q][sel]
    out = np.stack([us, vs, nx, ny, width[sel], peak, flags.astype(float)], axis=1)
    rank = np.argsort(np.argsort(-score))[lq[sel]]
    order = np.lexsort((us, vs, rank))
    return out[order], rank[order], steep[sel][order]


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
