"""report.html in pieces (issue 36): the figures' ASCII text is written apart from the
tables' text, whose few characters beyond Latin-1 would make the whole 0.6 MB page a
text of two bytes a character (joined, searched for headings and encoded as such)."""

from __future__ import annotations

import json

import pytest

from kinecal.identification import calibrate
from kinecal.report import (
    _calibration,
    _format,
    calibration_summary,
    pose_errors,
    render_calibration_report,
)
from kinecal.simulation import LaserTracker, experiment2


@pytest.fixture(scope="module")
def parts_and_page():
    twin = experiment2(31, tracker=LaserTracker(5e-6, 0.0), n_side=5)
    result = calibrate(twin.truth.robot, twin.train, "full")
    summary = json.loads(json.dumps(calibration_summary(result), default=float))
    poses = pose_errors(result, twin.train)
    parts = _calibration._report_parts(summary, result.calibrated, poses)
    return parts, render_calibration_report(summary, result.calibrated, poses)


def test_pieces_are_the_page_and_the_figures_stay_ascii(parts_and_page):
    parts, html = parts_and_page
    stamp = len("kinecal 0.0.0, 2026-01-01 00:00")  # the minute may turn in between
    joined = "".join(parts)
    assert len(joined) == len(html) and joined[-5000:] == html[-5000:]
    assert joined.count("<h2") == html.count("<h2") and "<nav class=toc>" in joined
    figures = max(parts, key=len)
    assert "<svg" in figures and figures.isascii()
    assert len(figures) > 0.5 * len(joined) > stamp
    assert not all(p.isascii() for p in parts)  # the tables have '—', '≈', ...


def test_a_heading_after_the_body_still_joins_the_table_of_contents():
    body = "<h2>A</h2>\n<h2>B</h2>\n<h2>C</h2>"
    parts = _format.page_parts("t", body, ["\n<h2>D</h2>"])
    assert len(parts) == 2 and parts[0].count("<li>") == 4
    plain = _format.page_parts("t", body, ["\n<svg></svg>"])
    assert len(plain) == 3 and plain[1] == "\n<svg></svg>"
    assert plain[0].count("<li>") == 3
