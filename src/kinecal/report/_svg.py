"""A small SVG plotting module: the report's figures without matplotlib.

A :class:`Figure` holds :class:`Panel` s; a panel maps data to pixels on linear or
logarithmic axes, draws its frame, grid, ticks and axis labels (with units: the caller
writes them into the label), and collects marks: dots (scatter), lines, steps, bars,
polygons (violins), heat-map cells, a colour bar and a legend.

Marks are written as integers in tenths of a pixel inside a ``scale(.1)`` group, one
series at a time (no Python loop per point in this module: :mod:`kinecal._numtext`, about
a millisecond for 10^5 points). Dots are zero-length path segments with round caps:
one ``<path>`` per series and colour, about 14 bytes a point.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from kinecal._numtext import int_row_groups, int_rows
from kinecal.report._format import e
from kinecal.typing import ArrayLike, Float, Int

__all__ = [
    "COLORS",
    "Figure",
    "Panel",
    "colormap",
    "decimate",
    "limits",
    "ticks",
]

COLORS = ("#7f7f7f", "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b")
S = 10  # marks are written in 1/S pixel
FONT = 11.0  # px
_CHAR = 0.58  # mean glyph width of a sans-serif font, in font sizes

# Colour maps as anchors (evenly spaced), interpolated linearly in RGB.
_MAPS = {
    # viridis at 0, 1/9, ..., 1 (the matplotlib colour map's published values)
    "viridis": (
        "#440154 #482878 #3e4989 #31688e #26828e #1f9e89 #35b779 #6ece58 #b5de2b #fde725"
    ).split(),
    # blue - white - red, for correlations in [-1, 1]
    "diverging": "#2b5fa8 #6f9fd0 #c4d8ec #f7f7f7 #f3c9b4 #d87a5c #b2182b".split(),
}


def colormap(v: ArrayLike, lo: float, hi: float, name: str = "viridis") -> list[str]:
    """Hex colours of values ``v`` on the map ``name`` over ``[lo, hi]`` (clipped)."""
    anchors = np.array(
        [[int(h[i : i + 2], 16) for i in (1, 3, 5)] for h in _MAPS[name]], float
    )
    t = np.clip((np.asarray(v, float) - lo) / ((hi - lo) or 1.0), 0.0, 1.0)
    pos = t * (len(anchors) - 1)
    k = np.minimum(pos.astype(int), len(anchors) - 2)
    f = (pos - k)[..., None]
    rgb = np.rint(anchors[k] * (1 - f) + anchors[k + 1] * f).astype(int)
    code = (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
    return [f"#{c:06x}" for c in np.ravel(code).tolist()]


def decimate(values: ArrayLike, max_points: int = 5000) -> Int:
    """Indices of at most about ``max_points`` points to draw of a series.

    ``values`` (N,) or (N, k): the points' sizes (e.g. |error|). Below the limit all
    points; above, the largest 5 % (by the row maximum of ``values``: the extremes stay
    visible) plus evenly spaced ones of the others, in their original order.
    """
    a = np.abs(np.asarray(values, float))
    a = a.reshape(a.shape[0], -1).max(axis=1) if a.ndim > 1 else a
    n = a.size
    if n <= max_points:
        return np.arange(n)
    n_top = max_points // 20
    top = np.argpartition(-a, n_top)[:n_top]
    keep = np.zeros(n, bool)
    keep[top] = True
    rest = np.flatnonzero(~keep)
    keep[rest[np.linspace(0, rest.size - 1, max_points - n_top).astype(np.intp)]] = True
    return np.flatnonzero(keep)


def limits(
    *values: ArrayLike, log: bool = False, zero: bool = False, pad: float = 0.04
) -> tuple[float, float]:
    """Axis limits spanning finite ``values`` (positive ones on a log axis), padded."""
    v = np.concatenate(
        [np.ravel(np.asarray(x, float)) for x in values] or [np.zeros(0)]
    )
    v = v[np.isfinite(v) & (v > 0)] if log else v[np.isfinite(v)]
    if v.size == 0:
        return (0.1, 10.0) if log else (0.0, 1.0)
    lo, hi = float(v.min()), float(v.max())
    if log:
        a, b = math.log10(lo), math.log10(hi)
        d = max(b - a, 0.3) * pad
        return 10 ** (a - d), 10 ** (b + d)
    if zero:
        lo, hi = min(lo, 0.0), max(hi, 0.0)
    d = (hi - lo) or max(abs(hi), 1.0)
    return lo - (0.0 if zero and lo == 0 else pad * d), hi + pad * d


def ticks(lo: float, hi: float, log: bool = False, n: int = 5) -> list[float]:
    """About ``n`` round tick values in [lo, hi] (1, 2, 5 x 10^k; decades on log axes)."""
    if log:
        a, b = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
        mult = (1.0,) if b - a > 2 else (1.0, 2.0, 5.0)
        return [
            m * 10.0**k
            for k in range(a, b + 1)
            for m in mult
            if lo <= m * 10.0**k <= hi
        ]
    if not hi > lo:
        return [lo]
    raw = (hi - lo) / max(n, 1)
    mag = 10.0 ** math.floor(math.log10(raw)) if raw > 0 else 1.0
    step = min((m * mag for m in (1.0, 2.0, 5.0, 10.0)), key=lambda s: abs(raw / s - 1))
    first = math.ceil(lo / step - 1e-9)
    out = [k * step for k in range(first, math.floor(hi / step + 1e-9) + 1)]
    return [0.0 if abs(t) < step * 1e-9 else t for t in out]


def _tick_label(t: float, ts: list[float], log: bool = False) -> str:
    if len(ts) > 1 and not log:
        step = min(abs(b - a) for a, b in itertools.pairwise(ts))
        if 1e-4 <= step and max(abs(x) for x in ts) < 1e6:
            d = max(0, -math.floor(math.log10(step) + 1e-9))
            return f"{t:.{d}f}"
    return f"{t:g}"


def _ints(v: ArrayLike) -> NDArray[np.int64]:
    return np.rint(np.asarray(v, float)).astype(np.int64)


def _repeat(fmt: str, *columns: NDArray[np.int64]) -> str:
    """``fmt`` (one ``%d`` per column) filled row by row and concatenated: the text of
    ``(fmt * n) % values``, built as arrays of digits for a long series
    (:func:`kinecal._numtext.int_rows`: 2-4x faster than ``%``, issue 36)."""
    return int_rows(fmt, columns)


def _text_w(s: str, size: float = FONT) -> float:
    return _CHAR * size * len(s)


class Panel:
    """One plot area at (x, y) with size (w, h) [px] in its figure; data limits
    ``xlim``, ``ylim`` (log axes: positive), labels with units."""

    def __init__(
        self,
        x: float,
        y: float,
        w: float,
        h: float,
        xlim: tuple[float, float],
        ylim: tuple[float, float],
        *,
        xlabel: str = "",
        ylabel: str = "",
        title: str = "",
        xlog: bool = False,
        ylog: bool = False,
        xticks: Sequence[tuple[float, str]] | None = None,
        grid: bool = True,
    ) -> None:
        self.x, self.y, self.w, self.h = x, y, w, h
        self.xlim, self.ylim, self.xlog, self.ylog = xlim, ylim, xlog, ylog
        self.xlabel, self.ylabel, self.title = xlabel, ylabel, title
        self.xticks, self.grid = xticks, grid
        self.marks: list[str] = []  # in 1/S px
        self.over: list[str] = []  # in px, drawn last (legends, notes)

    # ------------------------------------------------------------------ mapping
    def _map(self, v: ArrayLike, lim: tuple[float, float], log: bool) -> Float:
        a = np.asarray(v, float)
        lo, hi = lim
        if log:
            a = np.log10(np.clip(a, lo, hi))
            lo, hi = math.log10(lo), math.log10(hi)
        return (np.clip(a, lo, hi) - lo) / ((hi - lo) or 1.0)

    def px(self, v: ArrayLike) -> Float:
        """x pixel [px] of data values."""
        return self.x + self.w * self._map(v, self.xlim, self.xlog)

    def py(self, v: ArrayLike) -> Float:
        """y pixel [px] of data values (up is up)."""
        return self.y + self.h * (1.0 - self._map(v, self.ylim, self.ylog))

    # ------------------------------------------------------------------ marks
    def dots(
        self, x: ArrayLike, y: ArrayLike, color: str, size: float = 3.0, alpha=0.8
    ) -> None:
        """Scatter: round dots of diameter ``size`` [px]."""
        X, Y = _ints(self.px(x) * S), _ints(self.py(y) * S)
        if not X.size:
            return
        d = _repeat("M%d %dh0", X, Y)
        self.marks.append(
            f'<path d="{d}" stroke="{color}" stroke-width="{size * S:g}" '
            f'stroke-linecap="round" stroke-opacity="{alpha}"/>'
        )

    def dot_groups(
        self,
        x: ArrayLike,
        y: ArrayLike,
        counts: Sequence[int],
        colors: Sequence[str],
        size: float = 3.0,
        alpha: float = 0.8,
    ) -> None:
        """:meth:`dots` of consecutive groups of the points: the first ``counts[0]``
        in ``colors[0]``, the next ``counts[1]`` in ``colors[1]``, ... (empty groups
        draw nothing); the points mapped and written at once (issue 36)."""
        X, Y = _ints(self.px(x) * S), _ints(self.py(y) * S)
        drawn = [(int(c), color) for c, color in zip(counts, colors) if c > 0]
        if not drawn:
            return
        ends = np.cumsum([c for c, _ in drawn])
        texts = int_row_groups("M%d %dh0", (X, Y), ends[:-1].tolist())
        for (_, color), d in zip(drawn, texts):
            self.marks.append(
                f'<path d="{d}" stroke="{color}" stroke-width="{size * S:g}" '
                f'stroke-linecap="round" stroke-opacity="{alpha}"/>'
            )

    def line(
        self,
        x: ArrayLike,
        y: ArrayLike,
        color: str,
        width: float = 1.5,
        dash: str = "",
        alpha: float = 1.0,
    ) -> None:
        """A polyline through the points (in order)."""
        X, Y = _ints(self.px(x) * S), _ints(self.py(y) * S)
        pts = _repeat("%d,%d ", X, Y)
        extra = f' stroke-dasharray="{dash}"' if dash else ""
        self.marks.append(
            f'<polyline points="{pts}" fill="none" stroke="{color}" '
            f'stroke-width="{width * S:g}" stroke-opacity="{alpha}"{extra}/>'
        )

    def steps(self, edges: ArrayLike, counts: ArrayLike, color: str, width=1.6) -> None:
        """A histogram outline: ``counts`` (k,) over bins ``edges`` (k + 1,)."""
        ed, c = np.asarray(edges, float), np.asarray(counts, float)
        x = np.repeat(ed, 2)
        y = np.concatenate([[0.0], np.repeat(c, 2), [0.0]])
        self.line(x, y, color, width)

    def bars(
        self,
        x0: ArrayLike,
        x1: ArrayLike,
        y0: ArrayLike,
        y1: ArrayLike,
        color: str,
        alpha: float = 0.85,
    ) -> None:
        """Filled rectangles [x0, x1] x [y0, y1] (data units)."""
        X0, X1, Y0, Y1 = np.broadcast_arrays(
            _ints(self.px(x0) * S),
            _ints(self.px(x1) * S),
            _ints(self.py(y0) * S),
            _ints(self.py(y1) * S),
        )
        top, hgt, wid = np.minimum(Y0, Y1), np.abs(Y0 - Y1), X1 - X0
        d = _repeat("M%d %dh%dv%dh%dz", X0, top, wid, hgt, -wid)
        self.marks.append(f'<path d="{d}" fill="{color}" fill-opacity="{alpha}"/>')

    def polygon(
        self, x: ArrayLike, y: ArrayLike, fill: str, alpha: float = 0.5, stroke=""
    ) -> None:
        X, Y = _ints(self.px(x) * S), _ints(self.py(y) * S)
        pts = _repeat("%d,%d ", X, Y)
        st = f' stroke="{stroke}" stroke-width="{S}"' if stroke else ""
        self.marks.append(
            f'<polygon points="{pts}" fill="{fill}" fill-opacity="{alpha}"{st}/>'
        )

    def text(
        self, x: float, y: float, s: str, anchor: str = "start", size: float = FONT
    ) -> None:
        """Text at data coordinates."""
        px, py = float(self.px(x)), float(self.py(y))
        self.over.append(
            f'<text x="{px:.1f}" y="{py:.1f}" font-size="{size:g}" '
            f'text-anchor="{anchor}">{e(s)}</text>'
        )

    def legend(self, items: Sequence[tuple[str, str]], where: str = "right") -> None:
        """Legend of (label, colour) in a corner ('right': top right, 'left': top left)."""
        if not items:
            return
        wid = max(_text_w(lab, 10) for lab, _ in items) + 26
        x0 = self.x + self.w - wid - 6 if where == "right" else self.x + 6
        y0 = self.y + 6
        out = [
            f'<rect x="{x0:.1f}" y="{y0:.1f}" width="{wid:.1f}" '
            f'height="{14 * len(items) + 6}" fill="#fff" fill-opacity="0.85" '
            'stroke="#ccc"/>'
        ]
        for k, (lab, col) in enumerate(items):
            yy = y0 + 12 + 14 * k
            out.append(
                f'<path d="M{x0 + 6:.1f} {yy - 3.5:.1f}h12" stroke="{col}" '
                f'stroke-width="4"/><text x="{x0 + 22:.1f}" y="{yy:.1f}" '
                f'font-size="10">{e(lab)}</text>'
            )
        self.over.append("".join(out))

    # ------------------------------------------------------------------ output
    def svg(self) -> str:
        x, y, w, h = self.x, self.y, self.w, self.h
        out = [
            f'<rect x="{x:.1f}" y="{y:.1f}" width="{w:.1f}" height="{h:.1f}" fill="#fff"/>'
        ]
        xt = (
            [(t, lab) for t, lab in self.xticks]
            if self.xticks is not None
            else _labelled(
                ticks(*self.xlim, log=self.xlog, n=max(2, int(w // 90))), self.xlog
            )
        )
        yt = _labelled(
            ticks(*self.ylim, log=self.ylog, n=max(2, int(h // 45))), self.ylog
        )
        grid, labels = [], []
        for t, lab in xt:
            p = float(self.px(t))
            grid.append(f"M{p:.1f} {y:.1f}v{h:.1f}")
            labels.append(
                f'<text x="{p:.1f}" y="{y + h + 13:.1f}" text-anchor="middle">{e(lab)}</text>'
            )
        for t, lab in yt:
            p = float(self.py(t))
            grid.append(f"M{x:.1f} {p:.1f}h{w:.1f}")
            labels.append(
                f'<text x="{x - 4:.1f}" y="{p + 3.5:.1f}" text-anchor="end">{e(lab)}</text>'
            )
        if self.grid and grid:
            out.append(f'<path d="{"".join(grid)}" stroke="#e6e6e6" stroke-width="1"/>')
        out.append(f'<g transform="scale({1 / S:g})">{"".join(self.marks)}</g>')
        out.append(
            f'<rect x="{x:.1f}" y="{y:.1f}" width="{w:.1f}" height="{h:.1f}" '
            'fill="none" stroke="#888"/>'
        )
        out.append(f'<g font-size="10" fill="#333">{"".join(labels)}</g>')
        if self.xlabel:
            out.append(
                f'<text x="{x + w / 2:.1f}" y="{y + h + 30:.1f}" '
                f'text-anchor="middle">{e(self.xlabel)}</text>'
            )
        if self.ylabel:
            lw = max((_text_w(lab, 10) for _, lab in yt), default=10.0)
            cx, cy = x - lw - 12, y + h / 2
            out.append(
                f'<text x="{cx:.1f}" y="{cy:.1f}" text-anchor="middle" '
                f'transform="rotate(-90 {cx:.1f} {cy:.1f})">{e(self.ylabel)}</text>'
            )
        if self.title:
            out.append(
                f'<text x="{x:.1f}" y="{y - 7:.1f}" font-weight="bold">{e(self.title)}</text>'
            )
        out += self.over
        return "".join(out)


def _labelled(ts: list[float], log: bool = False) -> list[tuple[float, str]]:
    return [(t, _tick_label(t, ts, log)) for t in ts]


class Figure:
    """An SVG picture of ``width`` x ``height`` px holding panels and free marks."""

    def __init__(self, width: float, height: float, title: str = "") -> None:
        self.width, self.height, self.title = width, height, title
        self.panels: list[Panel] = []
        self.extra: list[str] = []  # px

    def panel(self, *args, **kwargs) -> Panel:
        p = Panel(*args, **kwargs)
        self.panels.append(p)
        return p

    def heatmap(
        self,
        x: float,
        y: float,
        cell: float,
        values: Float,
        lo: float,
        hi: float,
        cmap: str = "diverging",
        levels: int = 21,
    ) -> None:
        """A matrix of cells (rows downwards) at (x, y), ``cell`` px each, coloured in
        ``levels`` steps over [lo, hi]; NaN cells stay empty."""
        v = np.asarray(values, float)
        t = np.clip((v - lo) / ((hi - lo) or 1.0), 0.0, 1.0)
        lev = np.where(np.isfinite(v), np.rint(t * (levels - 1)), -1).astype(int)
        cols = colormap(np.linspace(lo, hi, levels), lo, hi, cmap)
        # The cells level by level (row by row in each: a stable sort), written at
        # once and cut into one path per level (np.unique would import numpy.ma).
        flat = lev.ravel()
        order = np.argsort(flat, kind="stable")
        order = order[flat[order] >= 0]
        counts = np.bincount(flat[order], minlength=levels)
        used = np.flatnonzero(counts)
        i, j = np.divmod(order, lev.shape[1])
        ends = np.cumsum(counts[used])[:-1].tolist()
        texts = int_row_groups("M%d %dh1v1h-1z", (j, i), ends) if used.size else []
        paths = [
            f'<path d="{d}" fill="{cols[k]}"/>' for k, d in zip(used.tolist(), texts)
        ]
        self.extra.append(
            f'<g transform="translate({x:.1f} {y:.1f}) scale({cell:g})" '
            f'shape-rendering="crispEdges">{"".join(paths)}</g>'
        )

    def colorbar(
        self,
        x: float,
        y: float,
        w: float,
        h: float,
        lo: float,
        hi: float,
        label: str,
        cmap: str = "viridis",
    ) -> None:
        """A vertical colour bar with ticks and a label (with its unit)."""
        n = 32
        cols = colormap(np.linspace(hi, lo, n), lo, hi, cmap)
        step = h / n
        out = [
            f'<rect x="{x:.1f}" y="{y + k * step:.2f}" width="{w:.1f}" '
            f'height="{step + 0.3:.2f}" fill="{c}"/>'
            for k, c in enumerate(cols)
        ]
        out.append(
            f'<rect x="{x:.1f}" y="{y:.1f}" width="{w:.1f}" height="{h:.1f}" '
            'fill="none" stroke="#888"/>'
        )
        ts = ticks(lo, hi, n=5)
        for t, lab in _labelled(ts):
            py = y + h * (1 - (t - lo) / ((hi - lo) or 1.0))
            out.append(
                f'<path d="M{x + w:.1f} {py:.1f}h3" stroke="#888"/><text x="{x + w + 5:.1f}" '
                f'y="{py + 3.5:.1f}" font-size="10">{e(lab)}</text>'
            )
        cx, cy = (
            x
            + w
            + 20
            + max((_text_w(lab, 10) for _, lab in _labelled(ts)), default=10.0),
            y + h / 2,
        )
        out.append(
            f'<text x="{cx:.1f}" y="{cy:.1f}" text-anchor="middle" '
            f'transform="rotate(-90 {cx:.1f} {cy:.1f})">{e(label)}</text>'
        )
        self.extra.append("".join(out))

    def text(
        self,
        x: float,
        y: float,
        s: str,
        *,
        size: float = FONT,
        anchor: str = "start",
        rotate: float = 0.0,
        bold: bool = False,
    ) -> None:
        rot = f' transform="rotate({rotate:g} {x:.1f} {y:.1f})"' if rotate else ""
        fw = ' font-weight="bold"' if bold else ""
        self.extra.append(
            f'<text x="{x:.1f}" y="{y:.1f}" font-size="{size:g}" '
            f'text-anchor="{anchor}"{rot}{fw}>{e(s)}</text>'
        )

    def svg(self) -> str:
        """The SVG element (standalone: with its namespace, usable as a .svg file)."""
        head = (
            f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {self.width:g} '
            f'{self.height:g}" width="{self.width:g}" height="{self.height:g}" '
            f'font-family="Helvetica,Arial,sans-serif" font-size="{FONT:g}">'
        )
        title = f"<title>{e(self.title)}</title>" if self.title else ""
        bg = f'<rect width="{self.width:g}" height="{self.height:g}" fill="#fff"/>'
        body = "".join(p.svg() for p in self.panels) + "".join(self.extra)
        return f"{head}{title}{bg}{body}</svg>"
