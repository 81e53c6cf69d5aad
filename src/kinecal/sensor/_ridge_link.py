"""Linking ridge points into curves and keeping one centre per stripe cross-section.

Part of the ridge detector (:mod:`kinecal.sensor._ridge`, which states the rules). All
steps are vectorised over the points: neighbours are found by binary search on the
points' pixel keys, curves by a union-find with pointer jumping.
"""

from __future__ import annotations

import numpy as np

from kinecal.typing import Float

__all__ = [
    "components",
    "curvature",
    "link_edges",
    "one_per_section",
    "smooth_over_edges",
]

# Backward neighbours within two pixels (dx, dy): each pair of points is tested once.
_OFFSETS = tuple(
    (dx, dy) for dy in (-2, -1, 0) for dx in (-2, -1, 0, 1, 2) if dy < 0 or dx < 0
)
_COS_LINK = float(np.cos(np.radians(30.0)))  # the normals of linked points agree


def link_edges(
    x: np.ndarray, y: np.ndarray, nx: Float, ny: Float, width: int
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(i, j)`` of points (integer pixels ``x, y``) that belong to one curve.

    Two points are linked when they are at most two pixels apart in u and v and their
    normals ``nx, ny`` differ by at most 30 deg (ridges crossing a stripe, as speckle
    makes on its flanks, are not linked to it). ``width`` is the image width.
    """
    n = x.size
    if n < 2:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    key = y.astype(np.int64) * width + x
    order = np.argsort(key, kind="stable")
    ks = key[order]
    dx, dy = np.array(_OFFSETS).T
    # every point's neighbours at all offsets in one search: queries (offsets, n)
    q = (ks[None, :] + (dy * width + dx)[:, None]).ravel()
    pos = np.minimum(np.searchsorted(ks, q), n - 1)
    xx = (x[order][None, :] + dx[:, None]).ravel()
    hit = np.flatnonzero((ks[pos] == q) & (xx >= 0) & (xx < width))
    i = order[hit % n]
    j = order[pos[hit]]
    same = np.abs(nx[i] * nx[j] + ny[i] * ny[j]) >= _COS_LINK
    return i[same], j[same]


def components(n: int, ei: np.ndarray, ej: np.ndarray) -> np.ndarray:
    """Curve labels 0..m-1 of ``n`` points linked by the pairs ``(ei, ej)``.

    Union-find, vectorised: every link hooks the larger root under the smaller, then
    pointer jumping flattens the trees; repeated until no link joins two trees.
    """
    lab = np.arange(n)
    while ei.size:
        li, lj = lab[ei], lab[ej]
        lo, hi = np.minimum(li, lj), np.maximum(li, lj)
        m = lo != hi
        if not m.any():
            break
        lab[hi[m]] = lo[m]  # any of several hooks of one root will do
        while True:
            nxt = lab[lab]
            if np.array_equal(nxt, lab):
                break
            lab = nxt
    return np.unique(lab, return_inverse=True)[1].reshape(-1)


def curvature(
    px: Float, py: Float, nx: Float, ny: Float, ei: np.ndarray, ej: np.ndarray
) -> tuple[Float, Float]:
    """Curvature vectors (toward the centre of curvature, length 1 / radius [1/px]).

    From the turn of the unit normal ``n`` between linked points at ``px, py``: along
    the tangent ``t`` of a curve ``dn/ds = -kappa t`` (kappa > 0 when the curve bends
    towards ``+n``), fitted by least squares over each point's links. The vector
    ``kappa n`` does not depend on the sign of ``n``.
    """
    n = px.size
    a = np.concatenate([ei, ej])
    b = np.concatenate([ej, ei])
    flip = np.where(nx[a] * nx[b] + ny[a] * ny[b] < 0, -1.0, 1.0)
    tx, ty = -ny[a], nx[a]  # tangent of a
    ds = (px[b] - px[a]) * tx + (py[b] - py[a]) * ty
    dn = (flip * nx[b] - nx[a]) * tx + (flip * ny[b] - ny[a]) * ty
    num = np.bincount(a, dn * ds, minlength=n)
    den = np.bincount(a, ds * ds, minlength=n)
    k = -num / np.maximum(den, 1e-9)
    return k * nx, k * ny


def smooth_over_edges(
    value: Float, ei: np.ndarray, ej: np.ndarray, rounds: int
) -> Float:
    """``value`` averaged ``rounds`` times with each point's linked neighbours."""
    n = value.size
    deg = 1.0 + np.bincount(ei, minlength=n) + np.bincount(ej, minlength=n)
    out = value
    for _ in range(rounds):
        s = out + np.bincount(ei, out[ej], minlength=n)
        s += np.bincount(ej, out[ei], minlength=n)
        out = s / deg
    return out


def one_per_section(
    section: np.ndarray,
    label: np.ndarray,
    score: Float,
    offset: Float,
    position: Float,
    cos: Float,
    near: float,
    n_curves: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Keep one point per crossing of a cross-section, and one curve per cross-section.

    ``section``: cross-section key of each point (its row, or ``H +`` its column);
    ``label``: its curve; ``score``: its curve's score (larger wins); ``offset``: its
    distance from its pixel; ``position``: its coordinate along the section (u in a
    row, v in a column); ``cos``: the cosine between its normal and its section
    (distances along the section times it are distances along the normal);
    ``n_curves``: the number of curve labels.

    Points of one curve in one section less than two pixels apart are one crossing
    (the point with the smallest ``offset`` stands for it); a curve may cross a section
    several times (a ring crosses a column twice). Of the curves in a section, the one
    with the best score keeps its crossings and the others lose theirs. Returns the
    kept points' indices, whether a lost crossing was within ``near`` pixels of each
    (along its normal),
    and per curve the sections it won and the sections it is in (a (2, n_curves)
    array).
    """
    m = n_curves
    # crossings: runs of one curve in one section, sorted along the section
    o = np.lexsort((position, label, section))
    s_o, l_o, p_o = section[o], label[o], position[o]
    new = np.ones(o.size, bool)
    new[1:] = (
        (s_o[1:] != s_o[:-1]) | (l_o[1:] != l_o[:-1]) | (p_o[1:] - p_o[:-1] >= 2.0)
    )
    crossing = np.cumsum(new) - 1
    o2 = np.lexsort((np.abs(offset[o]), crossing))
    first = np.ones(o2.size, bool)
    first[1:] = crossing[o2[1:]] != crossing[o2[:-1]]
    rep = o[o2[first]]  # one point per crossing, in section-curve-position order
    s_r, l_r, p_r = section[rep], label[rep], position[rep]
    # the best curve of each section
    o3 = np.lexsort((-score[rep], s_r))
    head = np.ones(o3.size, bool)
    head[1:] = s_r[o3[1:]] != s_r[o3[:-1]]
    group = np.cumsum(head) - 1
    best = l_r[o3[head]][group]  # winner label of each crossing's section (o3 order)
    win_r = np.empty(rep.size, bool)
    win_r[o3] = l_r[o3] == best
    new_pair = np.ones(rep.size, bool)
    new_pair[1:] = (s_r[1:] != s_r[:-1]) | (l_r[1:] != l_r[:-1])
    sections_in = np.bincount(l_r[new_pair], minlength=m)
    won = np.bincount(l_r[new_pair & win_r], minlength=m)
    # a lost crossing next to a kept one along the section
    o4 = np.lexsort((p_r, s_r))
    a, b = o4[:-1], o4[1:]
    pair = (s_r[a] == s_r[b]) & (win_r[a] != win_r[b])
    c_r = cos[rep]
    pair &= np.abs(p_r[a] - p_r[b]) * np.maximum(c_r[a], c_r[b]) < near
    flag = np.zeros(rep.size, bool)
    flag[np.where(win_r[a[pair]], a[pair], b[pair])] = True
    kept = np.flatnonzero(win_r)
    return rep[kept], flag[kept], np.stack([won, sections_in])
