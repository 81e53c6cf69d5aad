"""The report's figures as SVG text (no matplotlib), drawn with :mod:`._svg`.

The comparison figures follow the paper's Figures 11 and 15: (a) position error per point
before and after calibration, (b) histogram of error counts per method, (c) error counts
per direction (x, y, z) and method, (d) violin plot of the error distributions.
Diagnostics of one calibration: per-axis RMS, residuals against each joint angle,
parameter correlations (labelled, readable for 50+ parameters), singular values of the
scaled identification Jacobian, errors over the workspace (three projections).

Every function takes arrays in mm / deg and returns an ``<svg>`` element (usable inline
in HTML or as a .svg file). Scatter plots draw at most about ``MAX_POINTS`` points per
series (:func:`._svg.decimate` keeps the largest errors) and say so in the figure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from kinecal._stats import quantiles
from kinecal.report._format import e as esc
from kinecal.report._format import num
from kinecal.report._svg import COLORS, Figure, colormap, decimate, limits
from kinecal.typing import Float

__all__ = [
    "COLORS",
    "MAX_POINTS",
    "fig_axis_counts",
    "fig_axis_rms",
    "fig_correlation",
    "fig_error_histogram",
    "fig_errors_before_after",
    "fig_residuals_vs_joints",
    "fig_singular_values",
    "fig_violin",
    "fig_workspace",
]

MAX_POINTS = 5000
W = 760.0  # figure width [px]
L, R, T, B = 72.0, 16.0, 30.0, 46.0  # panel margins [px]


def _color(k: int) -> str:
    return COLORS[k % len(COLORS)]


def _drawn_note(fig: Figure, shown: int, total: int) -> None:
    if shown < total:
        fig.text(
            W - R,
            fig.height - 6,
            f"{shown} of {total} points drawn: the largest 5 % and an even sample of the "
            "others",
            size=9,
            anchor="end",
        )


def fig_errors_before_after(
    before_mm: Float,
    after_mm: Float,
    title: str = "",
    labels: tuple[str, str] = ("before (nominal)", "after (calibrated)"),
) -> str:
    """(a) 3-D position error of each point (N,) before and after calibration [mm]."""
    b, a = np.asarray(before_mm, float), np.asarray(after_mm, float)
    idx = decimate(np.column_stack([b, a]), MAX_POINTS)
    fig = Figure(W, 330, title or "position error before and after calibration")
    p = fig.panel(
        L,
        T,
        W - L - R,
        330 - T - B,
        (-0.5, max(b.size - 0.5, 0.5)),
        limits(b, a, log=True),
        xlabel="point index [-]",
        ylabel="position error [mm]",
        title=title or "(a) position error before and after calibration",
        ylog=True,
    )
    p.dots(idx, b[idx], _color(0), 3.0)
    p.dots(idx, a[idx], _color(1), 3.0)
    p.legend([(labels[0], _color(0)), (labels[1], _color(1))])
    _drawn_note(fig, idx.size, b.size)
    return fig.svg()


def _hist_edges(values: Sequence[Float], bins: int = 30) -> tuple[Float, bool]:
    """Bin edges from 0 to the 99.5th percentile of all values (to the maximum when
    that is less than 1.5 times it); True when larger values go to the last bin."""
    allv = np.concatenate([np.ravel(v) for v in values])
    q = float(quantiles(allv, [0.995])[0]) if allv.size else 1.0
    mx = float(allv.max()) if allv.size else 1.0
    hi = mx if mx <= 1.5 * q else q
    return np.linspace(0.0, hi or 1.0, bins + 1), hi < mx


def fig_error_histogram(
    errors_mm: Mapping[str, Float],
    title: str = "",
    *,
    log: bool = False,
    colors: Sequence[str] | None = None,
) -> str:
    """(b) histogram of the 3-D position errors (N,) per method [mm]; ``log``: bins of
    equal width on a logarithmic axis (for errors of different magnitudes)."""
    cols = list(colors) if colors else [_color(k + 1) for k in range(len(errors_mm))]
    clipped = False
    if log:
        pos = [np.asarray(v, float)[np.asarray(v) > 0] for v in errors_mm.values()]
        lo, hi = limits(*pos, log=True, pad=0.0)
        edges = np.geomspace(lo, hi, 41)
    else:
        edges, clipped = _hist_edges(list(errors_mm.values()))
    counts = {
        k: np.histogram(np.clip(v, edges[0], edges[-1]), bins=edges)[0]
        for k, v in errors_mm.items()
    }
    top = max((int(c.max()) for c in counts.values() if c.size), default=1)
    fig = Figure(W, 320)
    p = fig.panel(
        L,
        T,
        W - L - R,
        320 - T - B,
        (float(edges[0]), float(edges[-1])),
        (0.0, top * 1.08),
        xlabel="position error [mm]"
        + (" (the last bin holds the larger ones)" if clipped else ""),
        ylabel="count [points]",
        title=title or "(b) count of position errors",
        xlog=log,
    )
    items = []
    for k, (name, c) in enumerate(counts.items()):
        p.steps(edges, c, cols[k % len(cols)])
        items.append((name, cols[k % len(cols)]))
    p.legend(items)
    return fig.svg()


def fig_axis_counts(errors_xyz_mm: Mapping[str, Float]) -> str:
    """(c) counts of |error| along x, y and z of the user frame per method (N, 3) [mm]."""
    names = list(errors_xyz_mm)
    absv = {k: np.abs(np.asarray(v, float)) for k, v in errors_xyz_mm.items()}
    edges, clipped = _hist_edges(list(absv.values()), bins=20)
    counts = {
        k: [
            np.histogram(np.minimum(v[:, a], edges[-1]), bins=edges)[0]
            for a in range(3)
        ]
        for k, v in absv.items()
    }
    top = max((int(c.max()) for cs in counts.values() for c in cs), default=1)
    h = 300.0
    pw = (W - L - R - 2 * 24) / 3
    fig = Figure(W, h)
    for a, axis in enumerate("xyz"):
        p = fig.panel(
            L + a * (pw + 24),
            T,
            pw,
            h - T - B,
            (0.0, float(edges[-1])),
            (0.0, top * 1.08),
            xlabel=f"|error along {axis}| [mm]",
            ylabel="count [points]" if a == 0 else "",
            title="(c) count of errors in each direction" if a == 0 else "",
        )
        for k, name in enumerate(names):
            p.steps(edges, counts[name][a], _color(k + 1), 1.4)
        if a == 2:
            p.legend([(n, _color(k + 1)) for k, n in enumerate(names)])
    if clipped:
        fig.text(
            W - R, h - 4, "the last bin holds the larger ones", size=9, anchor="end"
        )
    return fig.svg()


def fig_axis_rms(rms_xyz_mm: Mapping[str, Sequence[float]], title: str = "") -> str:
    """RMS error along x, y, z [mm] per data set (bars; log axis when they differ a lot)."""
    names = list(rms_xyz_mm)
    vals = np.array([[float(x) for x in rms_xyz_mm[n]] for n in names]).reshape(-1, 3)
    fin = vals[np.isfinite(vals) & (vals > 0)]
    log = fin.size > 0 and fin.max() / fin.min() > 30
    ylim = (
        limits(fin, log=True) if log else (0.0, (fin.max() if fin.size else 1.0) * 1.1)
    )
    fig = Figure(W, 300)
    p = fig.panel(
        L,
        T,
        W - L - R - 180,
        300 - T - B,
        (-0.5, 2.5),
        ylim,
        xlabel="axis of the user frame",
        ylabel="RMS error [mm]",
        title=title or "RMS position error per axis",
        ylog=log,
        xticks=[(0.0, "x"), (1.0, "y"), (2.0, "z")],
    )
    width = 0.8 / max(len(names), 1)
    for k in range(len(names)):
        x0 = np.arange(3) - 0.4 + k * width
        v = np.where(np.isfinite(vals[k]), vals[k], np.nan)
        ok = np.isfinite(v)
        p.bars(
            x0[ok], x0[ok] + 0.9 * width, np.full(ok.sum(), ylim[0]), v[ok], _color(k)
        )
    p.legend([(n, _color(k)) for k, n in enumerate(names)])
    # the values, readable to the digit, beside the bars
    y = T + 14
    for k, n in enumerate(names):
        fig.text(W - R - 170, y, n, size=10, bold=True)
        fig.text(
            W - R - 170,
            y + 13,
            "x {}  y {}  z {}".format(*(num(v) for v in vals[k])),
            size=10,
        )
        y += 32
    return fig.svg()


def _density(v: Float, grid: Float) -> Float:
    """Gaussian kernel density of ``v`` on ``grid`` (Silverman's bandwidth), from a
    200-bin histogram: O(len(grid) x 200) whatever the number of values."""
    s = np.sort(v)
    q1, q3 = quantiles(s, [0.25, 0.75])
    sd = min(float(np.std(s)), float(q3 - q1) / 1.34) or float(np.std(s)) or 1e-9
    h = 1.06 * sd * s.size ** (-0.2)
    counts, edges = np.histogram(s, bins=200, range=(s[0], s[-1] + 1e-12))
    c = 0.5 * (edges[1:] + edges[:-1])
    z = (grid[:, None] - c[None, :]) / h
    return np.exp(-0.5 * z * z) @ counts


def fig_violin(errors_mm: Mapping[str, Float], title: str = "") -> str:
    """(d) violin plots of the 3-D position errors (N,) per method [mm], with the median
    (white bar), the quartiles (box) and the range (line)."""
    names = list(errors_mm)
    vals = [np.asarray(errors_mm[n], float) for n in names]
    ylim = limits(*vals, zero=True)
    fig = Figure(W, 330)
    p = fig.panel(
        L,
        T,
        W - L - R,
        330 - T - B,
        (0.4, len(names) + 0.6),
        ylim,
        xlabel="method",
        ylabel="position error [mm]",
        title=title or "(d) error distribution",
        xticks=[(k + 1.0, n) for k, n in enumerate(names)],
    )
    for k, v in enumerate(vals):
        if v.size < 2:
            continue
        x = k + 1.0
        grid = np.linspace(v.min(), v.max(), 96)
        d = _density(v, grid)
        d = 0.4 * d / (d.max() or 1.0)
        p.polygon(
            np.concatenate([x - d, (x + d)[::-1]]),
            np.concatenate([grid, grid[::-1]]),
            _color(k + 1),
            0.45,
            stroke=_color(k + 1),
        )
        lo, q1, med, q3, hi = quantiles(v, [0, 0.25, 0.5, 0.75, 1])
        p.line([x, x], [lo, hi], "#333", 1.0)
        p.bars([x - 0.04], [x + 0.04], [q1], [q3], "#333", 0.9)
        p.line([x - 0.08, x + 0.08], [med, med], "#fff", 2.0)
    return fig.svg()


def fig_residuals_vs_joints(q_deg: Float, res_mm: Float, names: Sequence[str]) -> str:
    """Residual components (N, 3) [mm] against each joint value (N, J): where periodic
    (transmission) errors show. ``names``: the joints' axis labels with units."""
    q, r = np.asarray(q_deg, float), np.asarray(res_mm, float)
    n = q.shape[1]
    cols = 3
    rows = -(-n // cols)
    pw, ph, gx, gy = (W - L - R - 2 * 40) / cols, 150.0, 40.0, 62.0
    h = T + rows * ph + (rows - 1) * gy + B + 10
    fig = Figure(W, h)
    idx = decimate(r, MAX_POINTS)
    ylim = limits(r[idx])
    colors = [_color(a + 1) for a in range(3)]
    for j in range(n):
        row, col = divmod(j, cols)
        p = fig.panel(
            L + col * (pw + gx),
            T + row * (ph + gy),
            pw,
            ph,
            limits(q[:, j]),
            ylim,
            xlabel=names[j],
            ylabel="residual [mm]" if col == 0 else "",
            title="residuals against joint angles (calibration data, after)"
            if j == 0
            else "",
        )
        # x, y and z one after the other, mapped and written at once (issue 36)
        x, m = np.tile(q[idx, j], 3), idx.size
        p.dot_groups(x, r[idx].T.ravel(), [m] * 3, colors, 2.4, 0.55)
        if j == 0:
            p.legend(
                [(f"{c} (user frame)", _color(a + 1)) for a, c in enumerate("xyz")]
            )
    _drawn_note(fig, idx.size, r.shape[0])
    return fig.svg()


def fig_correlation(corr: Float, names: Sequence[str], title: str = "") -> str:
    """Correlation matrix (k, k) of the estimated parameters, every row and column
    labelled with the parameter's name (small font and more compact cells for 50+)."""
    k = len(names)
    cell = float(np.clip(600.0 / max(k, 1), 8.0, 24.0))
    fs = float(np.clip(cell * 0.8, 6.5, 10.0))
    lw = max((0.56 * fs * len(s) for s in names), default=10.0)
    x0, y0 = lw + 10, T
    size = k * cell
    width = max(x0 + size + 110, 360.0)
    fig = Figure(width, y0 + size + lw + 14, title or "parameter correlations")
    fig.text(x0, T - 10, title or "parameter correlations [-]", bold=True)
    fig.heatmap(x0, y0, cell, np.asarray(corr, float), -1.0, 1.0)
    fig.extra.append(
        f'<rect x="{x0:.1f}" y="{y0:.1f}" width="{size:.1f}" height="{size:.1f}" '
        'fill="none" stroke="#888"/>'
    )
    labels = []
    for i, s in enumerate(names):
        c = (i + 0.5) * cell
        labels.append(
            f'<text x="{x0 - 4:.1f}" y="{y0 + c + 0.35 * fs:.1f}" '
            f'text-anchor="end">{esc(s)}</text>'
        )
        bx, by = x0 + c + 0.35 * fs, y0 + size + 4
        labels.append(
            f'<text x="{bx:.1f}" y="{by:.1f}" text-anchor="end" '
            f'transform="rotate(-90 {bx:.1f} {by:.1f})">{esc(s)}</text>'
        )
    fig.extra.append(f'<g font-size="{fs:g}" fill="#222">{"".join(labels)}</g>')
    fig.colorbar(
        x0 + size + 14,
        y0,
        14,
        min(size, 240.0),
        -1.0,
        1.0,
        "correlation [-]",
        "diverging",
    )
    return fig.svg()


def fig_singular_values(sv: Float) -> str:
    """Singular values of the scaled, column-normalised identification Jacobian."""
    s = np.asarray(sv, float)
    rel = s / s[0]
    fig = Figure(W, 280)
    p = fig.panel(
        L,
        T,
        W - L - R,
        280 - T - B,
        (0.5, s.size + 0.5),
        limits(rel, log=True),
        xlabel="index [-]",
        ylabel="s_i / s_max [-]",
        title=f"singular values (condition number {s[0] / s[-1]:.4g})",
        ylog=True,
    )
    i = np.arange(1, s.size + 1)
    p.line(i, rel, _color(1), 1.2)
    p.dots(i, rel, _color(1), 5.0, 1.0)
    return fig.svg()


def fig_workspace(p_user_mm: Float, err_mm: Float, title: str = "") -> str:
    """Errors over the workspace: the points (N, 3) [mm] in three projections of the user
    frame (equal scales), coloured by their error (N,) [mm], largest drawn on top."""
    P, e = np.asarray(p_user_mm, float), np.asarray(err_mm, float)
    idx = decimate(e, MAX_POINTS)
    idx = idx[np.argsort(e[idx], kind="stable")]
    lo, hi = float(e.min()) if e.size else 0.0, float(e.max()) if e.size else 1.0
    hi = hi if hi > lo else lo + max(abs(lo) * 0.1, 1e-6)
    levels = 16
    lev = np.clip(
        ((e[idx] - lo) / ((hi - lo) or 1.0) * levels).astype(int), 0, levels - 1
    )
    cols = colormap((np.arange(levels) + 0.5) / levels * (hi - lo) + lo, lo, hi)
    counts = np.bincount(lev, minlength=levels).tolist()
    runs = bool(np.all(lev[1:] >= lev[:-1]))  # (the errors sorted: unless NaN)
    centre = 0.5 * (P.min(axis=0) + P.max(axis=0)) if P.size else np.zeros(3)
    half = 0.52 * float(np.max(P.max(axis=0) - P.min(axis=0))) if P.size else 1.0
    half = half or 1.0
    pw = (W - L - R - 2 * 58 - 110) / 3
    h = T + pw + B + 6
    fig = Figure(W, h)
    for k, (a, b) in enumerate(((0, 1), (0, 2), (1, 2))):
        p = fig.panel(
            L + k * (pw + 58),
            T,
            pw,
            pw,
            (centre[a] - half, centre[a] + half),
            (centre[b] - half, centre[b] + half),
            xlabel=f"{'xyz'[a]} [mm]",
            ylabel=f"{'xyz'[b]} [mm]",
            title=(title or "errors over the workspace (user frame)") if k == 0 else "",
        )
        if runs:  # each level's points a run of idx: one path per level at once
            p.dot_groups(P[idx, a], P[idx, b], counts, cols, 3.2, 0.9)
            continue
        for level in range(levels):
            sel = idx[lev == level]
            if sel.size:
                p.dots(P[sel, a], P[sel, b], cols[level], 3.2, 0.9)
    fig.colorbar(W - R - 96, T, 14, pw, lo, hi, "position error [mm]")
    _drawn_note(fig, idx.size, e.size)
    return fig.svg()
