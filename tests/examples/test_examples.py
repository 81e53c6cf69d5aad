"""The real-data examples run and reach the accuracy their README states.

Studies (5-fold cross-validation of five models, and leave-one-out), so in the slow suite
(`make test-slow`, run by CI). The fast suite covers their steps on the same data:
tests/cli/test_real_data_cli.py (the UR10 poses calibrated and cross-validated from the
command line, the FR3 sessions scored on a new set-up), tests/identification/
test_nominal_check.py and tests/cli/test_issue_20_nominal_cli.py (the UR10 poses on the
CB-series table flagged), tests/identification/test_issue_25_robust.py (the FR3 camera data
cross-validated).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

pytestmark = pytest.mark.slow


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
    """Issue 20: the FIGAROH 'UR10' data are from a UR10e. On its own nominal table the
    frames-only error is 4 mm (12 mm on the CB table); the calibrated kinematic model
    predicts every left-out pose better than the nominal one and than FIGAROH's
    identification on the same folds (4.14-4.27 mm, from the issue)."""
    s = _run("ur10_mocap.py", tmp_path)
    cv = _cv(s)
    assert s["n"] == 23 and s["robot"] == "ur10e"
    nominal = cv["nominal (frames only)"]
    assert 3.5 < nominal < 4.6  # 12.2 mm on the CB-series table
    loo = {r["model"]: r["loo_rms_mm"] for r in s["cv"] if "loo_rms_mm" in r}
    assert loo["kinematic"] < loo["nominal (frames only)"]
    assert loo["kinematic"] <= 3.8 < 4.14  # issue 20: at most 3.8, aiming at 3.6
    # Priors keep the full model within a standard error of the kinematic one (issue
    # 11; 23 poses: the error's fold-to-fold standard error is 0.4-0.5 mm).
    se = {r["model"]: r["cv_se_mm"] for r in s["cv"]}
    assert cv["full"] <= cv["kinematic"] + se["kinematic"]
    # The right nominal passes the nominal check; the CB table fails it.
    assert s["fit_all"]["nominal_check"] == []
    cb = " ".join(s["cb_table_check"])
    assert "priors hold the fit back" in cb and "joint2.d" in cb
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
