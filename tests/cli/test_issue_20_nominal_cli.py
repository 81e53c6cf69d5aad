"""Issue 20 point 4: a calibration on the wrong nominal robot says so."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from kinecal.io import measurements_to_csv
from kinecal.robot import load_robot
from tests.helpers import calibrate_args

DATA = Path(__file__).resolve().parents[2] / "examples" / "data"


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


def test_issue_20_the_wrong_nominal_robot_is_named(run_cli, tmp_path):
    """The UR10e motion-capture data calibrated on the CB-series table: the report names
    the priors holding parameters back and the nominal mismatch; on the right table it
    says nothing of the kind."""
    import sys

    sys.path.insert(0, str(DATA.parent))
    try:
        from ur10_mocap import load
    finally:
        sys.path.remove(str(DATA.parent))
    meas = load()
    path = tmp_path / "ur10.csv"
    path.write_text(measurements_to_csv(meas, load_robot("ur10e")))
    codes = {}
    for robot in ("ur10", "ur10e"):
        out = tmp_path / robot
        res = run_cli(*calibrate_args(path, robot, out))
        assert res.returncode in (0, 3), res.stderr
        report = json.loads((out / "report.json").read_text())
        codes[robot] = {d["code"] for d in report["diagnostics"]}
    assert {"priors_held", "nominal_mismatch"} & codes["ur10"]
    assert not {"priors_held", "nominal_mismatch"} & codes["ur10e"]
