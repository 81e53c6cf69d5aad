"""kinecal._numtext writes numbers as ``%`` does, byte for byte, from arrays (issue 36:
residuals.csv and the report's SVG paths), and the writers use it."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from kinecal import _numtext
from kinecal._numtext import csv_lines, int_fields, int_rows, join_rows

# Values whose text is easy to get wrong: signed zeros, negatives that round to zero,
# exact and near halves at the 6th decimal, carries into the next digit or decade,
# the largest magnitudes the words hold.
SPECIAL = [
    0.0,
    -0.0,
    -1e-7,
    5e-7,
    -5e-7,
    1.5e-6,
    -2.5e-6,
    0.1234565,
    12.43158375,
    1.0000005,
    9.9999995,
    -99.99999951,
    9999.9999996,
    -999999.9999994,
    999999.49999,
    123456.0,
    1e-300,
]


def _reference(rows, x) -> str:
    line = "%d" + ",%.6f" * x.shape[1] + "\n"
    return "".join(line % (r, *v) for r, v in zip(rows.tolist(), x.tolist()))


@pytest.mark.parametrize("seed", range(40))
def test_csv_lines_are_the_text_of_percent_format(seed):
    rng = np.random.default_rng(seed)
    n, k = int(rng.integers(1, 60)), int(rng.integers(1, 19))
    x = rng.normal(0, 1, (n, k)) * 10.0 ** rng.integers(-9, 6, (n, k))
    if seed % 2:  # data typed with 7 or 8 decimals: halves at the 6th are common
        x = np.round(x, int(rng.integers(7, 9)))
    where = rng.integers(0, x.size, min(len(SPECIAL), x.size))
    x.ravel()[where] = np.array(SPECIAL)[: where.size]
    rows = rng.integers(-(10**5), 10**6, n)
    assert csv_lines(rows, x) == _reference(rows, x)


def test_csv_lines_leave_what_the_words_cannot_hold_to_percent():
    rows = np.arange(2, 4)
    for bad in (np.nan, np.inf, -np.inf, 1e6, -1e6, 999999.9999996, 1e300):
        assert csv_lines(rows, np.array([[1.0], [bad]])) is None
    assert csv_lines(np.array([2, 10**6]), np.ones((2, 1))) is None
    assert csv_lines(np.array([2, -(10**6)]), np.ones((2, 1))) is None
    assert csv_lines(np.zeros(0, int), np.zeros((0, 3))) == ""


FORMATS = ["M%d %dh0", "%d,%d ", "M%d %dh%dv%dh%dz", "M%d %dh1v1h-1z", "ab%d;;%dxyz%d"]


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("n", [1, 7, 600, 2500])
def test_int_rows_are_the_text_of_percent_format(fmt, n):
    rng = np.random.default_rng(n)
    k = fmt.count("%d")
    a = rng.integers(-20000, 90000, (n, k)) // 10 ** rng.integers(0, 5, (n, k))
    a.ravel()[: min(4, a.size)] = [0, -999999, 999999, -1][: min(4, a.size)]
    cols = [a[:, j] for j in range(k)]
    assert int_rows(fmt, cols) == (fmt * n) % tuple(a.ravel().tolist())
    big = a.copy()
    big[-1, -1] = 10**12  # beyond the words: % itself
    assert int_rows(fmt, [big[:, j] for j in range(k)]) == (fmt * n) % tuple(
        big.ravel().tolist()
    )


def test_int_rows_refuses_a_format_that_does_not_fit_the_columns():
    with pytest.raises(ValueError):
        int_rows("%d %s", [np.arange(3), np.arange(3)])
    with pytest.raises(ValueError):
        int_rows("%d", [np.arange(3), np.arange(3)])


def test_int_fields_and_join_rows():
    a = np.array([0, -5, 123456, -999999, 42])
    assert join_rows(["<", ">"], [int_fields(a)]) == "".join(f"<{v}>" for v in a)
    b = np.array([0, -5, 10**15, -(10**17), 42])  # the text path
    assert join_rows(["", ";"], [int_fields(b)]) == "".join(f"{v};" for v in b)
    with pytest.raises(TypeError):
        int_fields(np.ones(3))


def test_issue_36_residuals_csv_and_svg_paths_are_built_from_arrays(monkeypatch):
    """The writers go through the arrays (a % of 36 000 floats was 6 ms of a 2000-pose
    calibrate, the report's paths another 6 ms)."""
    from kinecal.report import _poses, _svg
    from kinecal.report._poses import PoseErrors

    calls: list[str] = []

    def spy(name, f):
        def g(*a, **k):
            calls.append(name)
            return f(*a, **k)

        return g

    monkeypatch.setattr(_poses, "csv_lines", spy("csv", _numtext.csv_lines))
    monkeypatch.setattr(_svg, "int_rows", spy("svg", _numtext.int_rows))
    rng = np.random.default_rng(1)
    n = 2000
    pe = PoseErrors(
        row=np.arange(2, n + 2),
        q=rng.normal(0, 90, (n, 6)),
        joint_units=("deg",) * 6,
        p_mm=rng.normal(0, 500, (n, 3)),
        before_mm=rng.normal(0, 1, (n, 3)),
        after_mm=rng.normal(0, 1e-2, (n, 3)),
    )
    text = pe.to_csv()
    assert calls == ["csv"] and text.count("\n") == n + 1
    fig = _svg.Figure(400, 300)
    panel = fig.panel(40, 20, 340, 250, (-1, 1), (-1, 1))
    panel.dots(rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), "#000")
    assert calls == ["csv", "svg"]


@pytest.mark.parametrize("n", [5, 3000])
def test_int_row_groups_cut_the_text_at_the_rows(n):
    rng = np.random.default_rng(n)
    a = rng.integers(-5000, 90000, (n, 2))
    bounds = sorted(set(rng.integers(0, n, 4).tolist()))
    got = _numtext.int_row_groups("M%d %dh0", [a[:, 0], a[:, 1]], bounds)
    edges = [0, *bounds, n]
    assert got == [
        ("M%d %dh0" * (hi - lo)) % tuple(a[lo:hi].ravel().tolist())
        for lo, hi in itertools.pairwise(edges)
    ]


@pytest.mark.parametrize("name", ["fig_workspace", "fig_residuals_vs_joints"])
def test_issue_36_figures_draw_their_dots_at_once(monkeypatch, name):
    """fig_workspace maps and writes a projection's points once (one group per colour
    level) where it drew 16 levels one by one, fig_residuals_vs_joints a joint's x, y
    and z residuals once: the same SVG, byte for byte."""
    from kinecal.report import _figures, _svg

    rng = np.random.default_rng(5)
    if name == "fig_workspace":
        args: tuple = (rng.normal(0, 300, (2000, 3)), rng.gamma(2.0, 0.01, 2000))
    else:
        names = [f"j{k + 1} [deg]" for k in range(6)]
        args = (
            rng.uniform(-170, 170, (2000, 6)),
            rng.normal(0, 0.01, (2000, 3)),
            names,
        )
    calls: list[int] = []
    dots = _svg.Panel.dots
    monkeypatch.setattr(
        _svg.Panel, "dots", lambda self, *a, **k: calls.append(1) or dots(self, *a, **k)
    )
    svg = getattr(_figures, name)(*args)
    assert calls == []  # no series drawn one by one

    def one_by_one(self, x, y, counts, colors, size=3.0, alpha=0.8):
        at = 0
        for c, color in zip(counts, colors):
            if c:
                self.dots(x[at : at + c], y[at : at + c], color, size, alpha)
            at += c

    monkeypatch.setattr(_svg.Panel, "dot_groups", one_by_one)
    assert getattr(_figures, name)(*args) == svg
    assert len(calls) >= 18  # the reference did draw group by group


def test_issue_36_heatmap_cells_are_written_at_once(monkeypatch):
    """The correlation heat map writes its cells in one text cut into a path per
    colour level (it wrote 21 levels one by one): the same SVG, byte for byte."""
    from kinecal.report import _svg

    rng = np.random.default_rng(2)
    corr = np.clip(rng.normal(0, 0.5, (53, 53)), -1, 1)
    corr[rng.random(corr.shape) < 0.05] = np.nan

    def drawn() -> str:
        fig = _svg.Figure(900, 900)
        fig.heatmap(10, 10, 12, corr, -1.0, 1.0)
        return fig.svg()

    calls: list[int] = []
    groups = _numtext.int_row_groups
    monkeypatch.setattr(
        _svg, "int_row_groups", lambda *a: calls.append(1) or groups(*a)
    )
    svg = drawn()
    assert calls == [1]
    # the reference: level by level, each level's cells in row order
    levels = 21
    t = np.clip((corr + 1.0) / 2.0, 0.0, 1.0)
    lev = np.where(np.isfinite(corr), np.rint(t * (levels - 1)), -1).astype(int)
    cols = _svg.colormap(np.linspace(-1.0, 1.0, levels), -1.0, 1.0, "diverging")
    paths = []
    for k in range(levels):
        i, j = np.nonzero(lev == k)
        if i.size:
            d = ("M%d %dh1v1h-1z" * i.size) % tuple(np.column_stack([j, i]).ravel())
            paths.append(f'<path d="{d}" fill="{cols[k]}"/>')
    assert "".join(paths) in svg


def test_every_integer_the_words_hold_is_written_as_percent_d():
    """All of -10^6 < v < 10^6 (the digit tables built from slices, issue 36)."""
    v = np.arange(-(10**6) + 1, 10**6)
    text = join_rows(["", "\n"], [int_fields(v)])
    assert text.split("\n")[:-1] == [str(x) for x in v.tolist()]
