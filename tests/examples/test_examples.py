"""The real-data examples run and reach the accuracy their README states."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def _run(script: str, out: Path) -> dict:
    subprocess.run(
        [sys.executable, str(EXAMPLES / script), "--out", str(out)],
        check=True,
        capture_output=True,
        text=True,
        cwd=EXAMPLES,
    )
    return json.loads((out / "summary.json").read_text())


def _cv(summary: dict) -> dict[str, float]:
    return {r["model"]: r["cv_rms_mm"] for r in summary["cv"]}


@pytest.mark.skipif(not EXAMPLES.is_dir(), reason="examples/ not in this checkout")
def test_ur10_mocap_example(tmp_path):
    s = _run("ur10_mocap.py", tmp_path)
    cv = _cv(s)
    assert s["n"] == 23
    nominal = cv["nominal (frames only)"]
    assert 10.0 < nominal < 14.0
    for model in ("kinematic, plain LS", "kinematic", "full"):
        assert cv[model] < 0.45 * nominal, (model, cv)
    # Priors never make the full model worse than the kinematic one (issue 11).
    assert cv["full"] <= cv["kinematic"] * 1.02
    assert (tmp_path / "model.yaml").is_file()
    assert (tmp_path / "ur10_poses.csv").is_file()


@pytest.mark.skipif(not EXAMPLES.is_dir(), reason="examples/ not in this checkout")
def test_franka_fr3_example(tmp_path):
    s = _run("franka_fr3_camera.py", tmp_path)
    cv = _cv(s)
    assert s["n"] == 114
    nominal = cv["nominal (frames only)"]
    # Priors never make the full model worse than the kinematic one (issue 11).
    assert cv["full"] <= cv["kinematic"] * 1.02
    assert cv["kinematic"] < 0.5 * nominal
    new = s["new_setup"]
    assert new["full_rms_mm"] < 0.6 * new["nominal_rms_mm"]
    assert new["full_rms_mm"] <= 1.02 * new["kinematic_rms_mm"]
