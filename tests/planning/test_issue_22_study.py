"""Issue 22's acceptance on the twin (slow: many calibrations) and the study's helpers."""

from __future__ import annotations

import pytest
from benchmarks import _planning


@pytest.mark.slow
def test_issue_22_planned_30_of_7000_reach_the_noise_floor():
    """30 planned poses of the 6955 experiment-2 candidates calibrate the full model to
    within 1.25x the noise floor on the held-out poses (six noise realisations), far
    better than 30 random ones (two draws per realisation); the predictions hold to 20 %."""
    res = _planning.tracker_study(ns=(30,), seeds=6, draws=2)
    assert res["candidates"] > 6900
    row = res["rows"][0]
    assert row["planned_ratio_mean"] <= 1.25, row
    assert row["random_ratio_mean"] >= row["planned_ratio_mean"] + 0.1, row
    for what in ("planned", "random"):
        assert row[f"{what}_ratio_mean"] == pytest.approx(
            row[f"predicted_{what}_ratio"], rel=0.2
        )


@pytest.mark.slow
def test_issue_22_planned_sensor_poses_beat_random_ones():
    """Sensor twin: 30 planned views of the four spheres (from 2000) against 30 random
    ones. The prediction is optimistic here (the paper's experiment-1 geometry departs
    from nominal by more than the default priors expect; docs/planning.md), so only the
    ordering and the random plans' prediction are checked."""
    res = _planning.sensor_study(ns=(30,), seeds=4, draws=2)
    row = res["rows"][0]
    assert row["planned_ratio_mean"] < 0.85 * row["random_ratio_mean"], row
    assert row["random_ratio_mean"] == pytest.approx(
        row["predicted_random_ratio"], rel=0.25
    )


def test_study_figures_are_written(tmp_path):
    pytest.importorskip("matplotlib")
    rows = [
        {
            "n": n,
            "planned_ratio_mean": 1 + 3 / n,
            "planned_ratio_sd": 0.02,
            "random_ratio_mean": 1 + 9 / n,
            "random_ratio_sd": 0.05,
            "predicted_planned_ratio": 1 + 3 / n,
            "predicted_random_ratio": 1 + 8 / n,
        }
        for n in (20, 30, 50)
    ]
    paths = _planning.figures({"tracker": {"rows": rows}}, tmp_path)
    assert [p.name for p in paths] == ["planning_tracker.png"]
    assert paths[0].stat().st_size > 10_000
