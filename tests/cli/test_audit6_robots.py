"""Audit 6: the user's own robot through simulate and evaluate (in-process): a URDF arm
whose wrist carries almost no gravity torque, and extrapolation warnings on a robot
that names its joints otherwise than the data's columns."""

from __future__ import annotations

from pathlib import Path

from tests.cli_contract import run_kinecal
from tests.helpers import calibrate_simulated

_URDF = Path(__file__).parents[1] / "data" / "vendor_urdf"


def test_simulate_a_urdf_arm_with_a_nearly_unloaded_wrist(capsys, tmp_path):
    """xArm6: the twin drew J6's compliance as deflection / its tiny gravity torque
    (0.48 rad/m) and simulate refused its own truth.yaml ('are these measurements of
    another robot, or is the robot file wrong?', exit 2)."""
    out = tmp_path / "sim"
    res = run_kinecal(
        capsys, "simulate", "--robot", _URDF / "xarm6_gripper.urdf", "--out", out,
        "--n-train", "40", "--n-test", "5", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    res = run_kinecal(
        capsys, "evaluate", out / "test.csv", "--model", out / "truth.yaml", "--json"
    )
    assert res.code == 0, str(res)


def test_extrapolation_names_the_data_column_of_a_named_joint(capsys, tmp_path):
    """UR5e data beyond the calibrated range: the warning named 'shoulder_pan' only; the
    data's column is j1_deg."""
    sim = tmp_path / "sim"
    args = ["--robot", "ur5e", "--out", sim, "--n-train", "40", "--n-test", "30", "-q"]
    assert run_kinecal(capsys, "simulate", *args).code == 0
    cal = tmp_path / "cal"
    calibrate_simulated(capsys, sim, cal)
    lines = (sim / "test.csv").read_text().splitlines()
    far = [lines[0]] + [ln.replace(ln.split(",")[0], "359.0", 1) for ln in lines[1:]]
    data = tmp_path / "far.csv"
    data.write_text("\n".join(far) + "\n")
    res = run_kinecal(
        capsys, "evaluate", data, "--model", cal / "model.yaml", "--json",
        "--allow-out-of-limits",
    )  # fmt: skip
    warned = [ln for ln in res.err.splitlines() if "lie outside the joint" in ln]
    assert warned, str(res)
    assert "line 2 (row 1) shoulder_pan (j1_deg) 359.0 deg (calibrated" in warned[0], (
        warned[0]
    )


def test_robot_option_given_a_model_or_a_data_file(capsys, tmp_path):
    """--robot DIR/model.yaml (the last calibration, for the next one): "unknown key
    'kinecal_model' (allowed: ...)"; --robot DATA.csv: "expected a mapping; got str"."""
    from tests.cli_contract import failed_with, make_point_data

    pt = make_point_data(tmp_path)
    res = run_kinecal(
        capsys, "calibrate", pt["train"], "--robot", pt["model"], "--out",
        tmp_path / "cal", "-q",
    )  # fmt: skip
    failed_with(res, "model.yaml", "a calibrated model", "not a robot file", "--model")
    res = run_kinecal(capsys, "fk", "--robot", pt["train"], "--", *["0"] * 6)
    failed_with(res, "train.csv", "a CSV table", "not a robot file")
    robot = tmp_path / "robot.yaml"
    robot.write_text("# j1_deg, j2_deg: a comment\n" + _ROBOT)
    res = run_kinecal(capsys, "fk", "--robot", robot, "--json", "--", *["0"] * 6)
    assert res.code == 0, str(res)


_ROBOT = """name: six-axis
convention: dh
units: {length: mm, angle: deg}
joints:
  - {theta_offset: 0, d: 300, a: 50, alpha: -90, limits: [-170, 170]}
  - {theta_offset: 0, d: 0, a: 300, alpha: 0, limits: [-170, 170]}
  - {theta_offset: 0, d: 0, a: 50, alpha: -90, limits: [-170, 170]}
  - {theta_offset: 0, d: 300, a: 0, alpha: 90, limits: [-170, 170]}
  - {theta_offset: 0, d: 0, a: 0, alpha: -90, limits: [-120, 120]}
  - {theta_offset: 0, d: 80, a: 0, alpha: 0, limits: [-360, 360]}
"""
