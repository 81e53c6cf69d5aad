"""HTML reports: self-contained, every figure visible in a real browser (issue 8), inline
SVG without matplotlib (issue 26)."""

from __future__ import annotations

import re
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from kinecal.identification import calibrate, compare_models, evaluate
from kinecal.report import (
    calibration_summary,
    pose_errors,
    read_pose_errors,
    render_calibration_report,
    write_calibration_report,
    write_comparison_report,
)
from kinecal.simulation import LaserTracker, experiment2

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.fixture(scope="module")
def twin():
    return experiment2(31, tracker=LaserTracker(5e-6, 0.0), n_side=6)


@pytest.fixture(scope="module")
def result(twin):
    return calibrate(twin.truth.robot, twin.train, "full")


@pytest.fixture(scope="module")
def reports(twin, result, tmp_path_factory):
    d = tmp_path_factory.mktemp("reports")
    cal = write_calibration_report(
        d / "calibration.html", result, twin.train, calibration_summary(result)
    )
    rows = compare_models(twin.truth.robot, twin.train, twin.test)
    cmp_ = write_comparison_report(
        d / "comparison.html",
        rows,
        twin.test,
        title="twin comparison",
        figure_dir=d / "figures",
    )
    return cal, cmp_


def _svgs(text: str) -> list[str]:
    return re.findall(r"<svg .*?</svg>", text, flags=re.S)


def _render(path):
    out = subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            f"--user-data-dir={path.parent / 'chromium-profile'}",
            "--virtual-time-budget=10000",
            "--dump-dom",
            path.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def test_reports_are_self_contained(reports):
    for path in reports:
        text = path.read_text()
        assert len(_svgs(text)) >= 5
        assert "data:image/png" not in text  # figures are inline SVG now
        assert not re.search(r'(src|href)="(?!#)', text)  # no external files or URLs
        assert "<link" not in text
        assert "[mm]" in text


def test_every_figure_is_well_formed_svg_with_units(reports):
    for path in reports:
        for svg in _svgs(path.read_text()):
            root = ET.fromstring(svg)  # raises on malformed XML
            assert root.tag == "{http://www.w3.org/2000/svg}svg"
            labels = [
                t.text or "" for t in root.iter("{http://www.w3.org/2000/svg}text")
            ]
            # every figure names a unit on its axes ([mm], [deg], [-], [points])
            assert any(re.search(r"\[(mm|deg|-|points)\]", s) for s in labels), labels


def test_issue_26_figure_files_for_readmes(reports):
    files = sorted(p.name for p in (reports[1].parent / "figures").iterdir())
    assert "a_errors_before_after.svg" in files and "d_violin.svg" in files
    for name in files:
        ET.parse(reports[1].parent / "figures" / name)


def test_calibration_report_content(reports):
    text = reports[0].read_text()
    for needle in (
        "User and tool frames",
        "(paper Tables 3, 6)",
        "Joint geometry",
        "Joint compliance",
        "Not identifiable",
        "joint3.d",
        "RMS before [mm]",
        "x [mm]",
        "r [deg]",
        "rad/m (per unit weight)",  # the compliance table, in model.yaml's units
        # issue 26: per-axis RMS, change from nominal with its significance
        "RMS x [mm]",
        "RMS z [mm]",
        "change from nominal",
        "|change| / std",
        "parameter correlations",
    ):
        assert needle in text, needle


def test_issue_38_compliance_in_physical_units(result):
    """lambda* / weight is compliance [rad/(N·m)], its inverse stiffness [N·m/rad]; with
    no known weight the two columns are left out rather than left empty."""
    from dataclasses import replace

    from kinecal.io import parameter_records
    from kinecal.report._tables import compliance_table

    cal = result.calibrated
    recs = [r for r in parameter_records(cal) if r["group"] == "load"]
    assert recs
    with_payload = compliance_table(replace(cal, reference_payload_kg=2.0))
    assert "compliance [rad/(N·m)]" in with_payload
    assert "stiffness [N·m/rad]" in with_payload
    # the row of joint2.lambda: value in rad/m, then compliance and stiffness (+- std)
    row = re.search(r"joint2\.lambda</td>(.*?)</tr>", with_payload).group(1)
    cells = [re.sub("<.*?>", "", c) for c in row.split("</td>")]
    lam = recs[1]["value"]
    c = float(cells[2].split("±")[0])
    assert c == pytest.approx(lam / (2.0 * 9.80665), rel=0.05, abs=1e-12)
    if c > 0 and "±" in cells[3]:
        k = float(cells[3].split("±")[0])
        assert k == pytest.approx(1 / c, rel=0.05)
    none = compliance_table(replace(cal, reference_payload_kg=None))
    if cal.model.robot.payload_kg is None:
        assert "rad/(N·m)" not in none and "<td></td>" not in none


def test_issue_26_change_from_nominal_and_significance(result, twin):
    summary = calibration_summary(result)
    html = render_calibration_report(summary, result.calibrated, None)
    p = next(p for p in summary["parameters"] if p["name"] == "joint2.a")
    change = p["value"] - p["start"]
    row = re.search(r"<td class=l>joint2\.a</td>(.*?)</tr>", html).group(1)
    cells = re.findall(r"<td>(.*?)</td>", row)
    assert float(cells[2]) == pytest.approx(change, rel=1e-3)  # mm, 4 digits
    assert float(cells[3]) == pytest.approx(abs(change) / p["std"], abs=0.06)


def test_issue_26_correlation_heat_map_is_labelled(result):
    summary = calibration_summary(result)
    html = render_calibration_report(summary, result.calibrated, None)
    svg = next(s for s in _svgs(html) if "parameter correlations" in s)
    labels = [
        t.text for t in ET.fromstring(svg).iter("{http://www.w3.org/2000/svg}text")
    ]
    names = summary["correlation"]["names"]
    assert len(names) >= 40
    for name in names:  # each name once on the rows, once on the columns
        assert labels.count(name) == 2, name


def test_issue_26_pose_errors_round_trip_and_match_evaluate(result, twin, tmp_path):
    pe = pose_errors(result, twin.train)
    path = tmp_path / "residuals.csv"
    path.write_text(pe.to_csv())
    back = read_pose_errors(path)
    np.testing.assert_array_equal(back.row, pe.row)
    for a, b in ((back.q, pe.q), (back.p_mm, pe.p_mm), (back.after_mm, pe.after_mm)):
        np.testing.assert_allclose(a, b, atol=1e-6)
    ev = evaluate(result.calibrated, twin.train)
    np.testing.assert_allclose(
        np.linalg.norm(back.after_mm, axis=1), ev.errors_mm, atol=2e-6
    )
    rms = np.sqrt(np.mean(back.before_mm**2, axis=0))
    np.testing.assert_allclose(rms, result.metrics_before.rms_xyz_mm, rtol=1e-5)


def test_issue_26_every_warning_has_its_full_list(result):
    summary = calibration_summary(result)
    summary["outliers"] = [
        {"row": 100 + k, "error_mm": 0.5, "z": 6.0} for k in range(14)
    ]
    message = (
        "14 rows have errors improbable under the noise of the others: rows 100, 101, "
        "102, 103, 104, 105, 106, 107, 108, 109 and 4 more; kept."
    )
    summary["warnings"] = [message]
    summary["diagnostics"] = [
        {
            "code": "outliers",
            "severity": "warning",
            "stage": "diagnose",
            "message": message,
            "rows": [100 + k for k in range(14)],
            "parameters": [],
        }
    ]
    html = render_calibration_report(summary, result.calibrated, None)
    box = html[: html.index("</div>")]
    assert "all 14 rows" in box
    for k in range(14):
        assert f"<td class=l>{100 + k}</td>" in box


@pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium not installed (apt-get install chromium)"
)
def test_reports_render_with_every_figure_visible(reports):
    expected = {reports[0]: 6, reports[1]: 5}
    for path, n in expected.items():
        dom = _render(path)
        m = re.search(r'data-figures="(\d+)/(\d+)"', dom)
        assert m, "the page did not finish loading"
        ok, total = int(m.group(1)), int(m.group(2))
        assert total >= n and ok == total, (path.name, ok, total)
        assert '<p class="bad">figure failed to load' not in dom


def test_issue_26_model_selection_in_the_report(result):
    from kinecal.identification import Candidate, Selection

    spec = result.calibrated.model.spec
    cands = [
        Candidate("kinematic", spec, 1.0, 27, 0.0213, 0.0011, 0.0195),
        Candidate("full", spec, 1.0, 50, 0.01718, 0.0009, 0.0157, chosen=True),
    ]
    sel = Selection(spec, 1.0, cands, ["a warning of the selection"], folds=5)
    summary = calibration_summary(result, extra={"model_selection": sel.as_dict()})
    html = render_calibration_report(summary, result.calibrated, None)
    assert "Model selection (--model auto, 5-fold cross-validation)" in html
    # the chosen candidate's held-out RMS is a row of the accuracy table
    assert "held-out, 5-fold CV of --model auto: full" in html
    assert "0.01718 ± 0.00090" in html
    assert "a warning of the selection" in html


def test_issue_26_orientation_errors_of_pose_data_in_the_accuracy_table(result):
    summary = calibration_summary(result)
    assert "orientation RMS [deg]" not in render_calibration_report(
        summary, result.calibrated, None
    )
    summary["before"].update(rot_rms_deg=0.2345678, rot_max_deg=0.61)
    summary["after"].update(rot_rms_deg=0.0123456, rot_max_deg=0.0456)
    html = render_calibration_report(summary, result.calibrated, None)
    assert "orientation RMS [deg]" in html and "<td>0.01235</td>" in html


def test_issue_36_headings_are_found_as_the_regular_expression_finds_them():
    """with_toc finds the <h2> headings by str.find and a match there: the matches of
    the expression's scan of the whole page."""
    import re

    from kinecal.report import _format

    body = (
        "<p>x</p><h2>One</h2><h2 class=x>not one</h2><h2 id=b-2>Two <small>s</small>"
        "</h2><h2<h2>Three\nlines</h2><svg><h2></svg></h2><h2 id=>bad</h2><h2>Four</h2>"
    )
    want = list(_format._H2.finditer(body))
    assert [m.span() for m in _format._heads(body)] == [m.span() for m in want]
    assert len(want) == 5 and _format.with_toc(body).count("<li>") == 5
    assert re.search("<nav class=toc>", _format.with_toc(body))
