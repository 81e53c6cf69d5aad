"""The SVG plotting module and the report's number formats (issue 26)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from kinecal._stats import quantiles
from kinecal.report import _figures as F
from kinecal.report._format import num, pm, ratio
from kinecal.report._svg import Figure, colormap, decimate, limits, ticks

NS = "{http://www.w3.org/2000/svg}"


def _texts(svg: str) -> list[str]:
    return [t.text or "" for t in ET.fromstring(svg).iter(f"{NS}text")]


def test_num_has_four_significant_digits():
    assert num(0.79724054) == "0.7972"
    assert num(12.3456) == "12.35"
    assert num(1105.0294) == "1105"
    assert num(0.0085637) == "0.008564"
    assert num(9.99996) == "10.00"  # rounding carries into the next decade
    assert num(2.5e-7) == "2.500e-07"
    assert num(0.5) == "0.5000"  # trailing zeros kept: columns line up
    assert num(None) == num(float("nan")) == "—"
    assert num(0.0) == "0"


def test_pm_rounds_the_value_to_the_std():
    assert pm(-1105.02938165, 0.00196195) == "-1105.0294 ± 0.0020"
    assert pm(44.2007, 0.43) == "44.20 ± 0.43"
    assert pm(1817.3, 828.0) == "1817 ± 828"
    assert pm(0.166031, None) == "0.166031"
    assert ratio(45.21) == "45.2" and ratio(None) == "—"


def test_decimate_keeps_the_extremes_and_the_order(rng):
    v = rng.standard_normal(20_000)
    v[[17, 12_345]] = [50.0, -60.0]
    idx = decimate(v, 5000)
    assert idx.size <= 5000 + 1
    assert 17 in idx and 12_345 in idx
    assert np.all(np.diff(idx) > 0)
    # the largest 5 % by size are all kept
    top = np.argsort(-np.abs(v))[: 5000 // 20]
    assert np.isin(top, idx).all()
    np.testing.assert_array_equal(decimate(v[:300], 5000), np.arange(300))


def test_ticks_are_round_and_inside():
    t = ticks(-0.022, 0.021)
    assert t == pytest.approx([-0.02, -0.01, 0.0, 0.01, 0.02])
    t = ticks(1e-4, 3.0, log=True)
    assert t == pytest.approx([1e-4, 1e-3, 1e-2, 0.1, 1.0])
    lo, hi = limits([0.3, 2.0], log=True)
    assert lo < 0.3 and hi > 2.0


def test_quantiles_equal_numpy(rng):
    v = rng.standard_normal(101)
    np.testing.assert_allclose(
        quantiles(v, [0, 0.25, 0.5, 0.99, 1]), np.quantile(v, [0, 0.25, 0.5, 0.99, 1])
    )


def test_colormap_ends():
    c = colormap([0.0, 1.0, 5.0], 0.0, 1.0)
    assert c == ["#440154", "#fde725", "#fde725"]
    assert colormap([-1.0, 1.0], -1.0, 1.0, "diverging") == ["#2b5fa8", "#b2182b"]


def test_dots_map_data_to_pixels():
    fig = Figure(200, 100)
    p = fig.panel(0, 0, 200, 100, (0.0, 2.0), (0.0, 1.0))
    p.dots([0.0, 1.0, 2.0], [0.0, 0.5, 1.0], "#000")
    svg = fig.svg()
    d = re.search(r'<path d="(M[^"]*)" stroke="#000"', svg).group(1)
    # tenths of a pixel: (0, 100) -> (0, 1000), (1, .5) -> (1000, 500), (2, 1) -> (2000, 0)
    assert d == "M0 1000h0M1000 500h0M2000 0h0"
    ET.fromstring(svg)


def test_large_scatter_is_decimated_and_says_so(rng):
    n = 20_000
    before = np.abs(rng.standard_normal(n)) + 0.5
    after = 0.01 * np.abs(rng.standard_normal(n))
    svg = F.fig_errors_before_after(before, after)
    drawn = sum(d.count("h0") for d in re.findall(r'd="(M[^"]*h0)"', svg))
    assert drawn <= 2 * (F.MAX_POINTS + 1)
    assert any("of 20000 points drawn" in t for t in _texts(svg))
    assert len(svg) < 200_000


def test_correlation_heat_map_labels_53_parameters(rng):
    names = [f"joint{k // 8 + 1}.param_{k}" for k in range(53)]
    A = rng.standard_normal((53, 200))
    C = np.corrcoef(A)
    svg = F.fig_correlation(C, names)
    labels = _texts(svg)
    for nm in names:
        assert labels.count(nm) == 2
    root = ET.fromstring(svg)
    group = next(g for g in root.iter(f"{NS}g") if g.findtext(f"{NS}text") == names[0])
    assert 6.0 <= float(group.get("font-size")) <= 10.0  # small, but readable
    cells = sum(p.get("d", "").count("h1v1") for p in root.iter(f"{NS}path"))
    assert cells == 53 * 53


@pytest.mark.parametrize("n", [1, 7, 3000])
def test_every_figure_is_valid_svg(rng, n):
    e = np.abs(rng.standard_normal((n, 3))) * 0.01
    errs = {
        "kinematic": np.linalg.norm(e, axis=1),
        "full": 0.5 * np.linalg.norm(e, axis=1),
    }
    svgs = [
        F.fig_errors_before_after(errs["kinematic"] * 50, errs["full"]),
        F.fig_error_histogram(errs),
        F.fig_error_histogram(errs, log=True),
        F.fig_axis_counts({"kinematic": e, "full": 0.5 * e}),
        F.fig_axis_rms({"before": [0.3, 0.3, 0.6], "after": [0.005, 0.005, 0.004]}),
        F.fig_violin(errs),
        F.fig_residuals_vs_joints(
            rng.uniform(-90, 90, (n, 6)), e, [f"J{j} [deg]" for j in range(6)]
        ),
        F.fig_singular_values(np.geomspace(1, 1e-4, 20)),
        F.fig_workspace(rng.uniform(-500, 500, (n, 3)), errs["full"]),
    ]
    for svg in svgs:
        root = ET.fromstring(svg)
        assert float(root.get("width")) > 0
        assert "nan" not in svg.lower().replace("nanometre", "")
