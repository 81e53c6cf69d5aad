"""kinecal.workflows: a command's work as one typed call (issue 32 point 1, calibrate);
the command line gives the same model and figures."""

from __future__ import annotations

import json

import numpy as np

from kinecal.io import load_model, read_measurements
from kinecal.robot import load_robot
from kinecal.workflows import CalibrationRun, calibrate_measurements


def test_calibrate_workflow_is_what_the_command_does(simulated_exp2, run_cli, tmp_path):
    robot = load_robot("fanuc-lrmate200id")
    meas = read_measurements(simulated_exp2 / "train.csv", robot, check=False)
    run = calibrate_measurements(robot, meas, cv_folds=3)
    assert isinstance(run, CalibrationRun)
    assert run.spec.name.startswith("auto:") and run.selection is not None
    assert run.held_out is not None
    assert [f.name for f in run.held_out.figures] == ["in-session", "new region"]
    extra = run.report_extra()
    assert set(extra) == {"model_selection", "cross_validation"}
    out = tmp_path / "cal"
    r = run_cli(
        "calibrate", str(simulated_exp2 / "train.csv"), "--robot", "fanuc-lrmate200id",
        "--cv", "3", "--out", str(out), "--no-report", "-q",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    cal = load_model(out / "model.yaml")
    assert cal.model.spec.name == run.spec.name
    np.testing.assert_allclose(cal.params, run.result.calibrated.params, atol=1e-12)
    cv = json.loads((out / "report.json").read_text())["cross_validation"]
    got = cv["figures"]["new region"]["model"]["rms_mm"]
    assert got == run.held_out.transfer.model.rms_mm


def test_calibrate_workflow_with_a_given_model_has_no_selection(simulated_exp2):
    robot = load_robot("fanuc-lrmate200id")
    meas = read_measurements(simulated_exp2 / "train.csv", robot, check=False)
    run = calibrate_measurements(robot, meas, model="kinematic")
    assert run.selection is None and run.held_out is None and run.report_extra() == {}
    assert run.spec.name == "kinematic" and run.result.success
