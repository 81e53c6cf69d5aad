"""Issue 20, point 3 from the command line: a mistake in the data stops the run with one
line naming file, line, column and value (exit 2); a finding that does not stop it is a
warning on stderr and in report.json. Before issue 20 each of these ran with exit 0."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinecal.identification import Measurements, calibrate
from kinecal.io import measurements_to_csv, save_model
from kinecal.robot import load_robot

REAL = Path(__file__).resolve().parents[1] / "data" / "real"
FANUC = load_robot("fanuc-lrmate200id")


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


def _edit_cell(text: str, line: int, column: str, value: str) -> str:
    lines = text.splitlines()
    k = lines[0].split(",").index(column)
    cells = lines[line - 1].split(",")
    cells[k] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


def _one_error_line(res, *parts: str) -> None:
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    err = res.stderr.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for p in parts:
        assert p in err, (p, err)


def test_issue_20_calibrate_refuses_a_joint_beyond_its_limit(tmp_path, run_cli):
    text = _edit_cell((REAL / "fr3_session_a.csv").read_text(), 12, "j4_deg", "5.0")
    f = tmp_path / "fr3.csv"
    f.write_text(text)
    args = [
        "calibrate",
        "--cv",
        "off",
        str(f),
        "--robot",
        "franka-fr3",
        "--model",
        "kinematic",
    ]
    args += ["--no-report", "-q"]
    res = run_cli(*args, "--out", str(tmp_path / "a"))
    _one_error_line(res, str(f), "line 12, column 'j4_deg': 5 is outside", "-8.7]")
    assert not (tmp_path / "a" / "model.yaml").exists()
    res = run_cli(*args, "--out", str(tmp_path / "b"), "--allow-out-of-limits")
    assert res.returncode == 0, res.stderr
    assert "warning" in res.stderr and "beyond the joint limits" in res.stderr
    report = json.loads((tmp_path / "b" / "report.json").read_text())
    assert [d["code"] for d in report["data_checks"]] == ["out_of_limits"]


def test_issue_20_calibrate_refuses_a_near_miss_column(tmp_path, run_cli):
    a = (REAL / "fr3_session_a.csv").read_text().splitlines()
    f = tmp_path / "m.csv"
    f.write_text("\n".join(["markers," + a[0]] + ["m1," + r for r in a[1:]]) + "\n")
    res = run_cli(
        "calibrate",
        "--cv",
        "off",
        str(f),
        "--robot",
        "franka-fr3",
        "--out",
        str(tmp_path / "o"),
    )
    _one_error_line(res, "column 'markers'", "did you mean 'marker'")


def test_issue_20_duplicates_reach_stderr_and_the_report(tmp_path, run_cli):
    lines = (REAL / "fr3_session_a.csv").read_text().splitlines()
    f = tmp_path / "dup.csv"
    f.write_text("\n".join([*lines, lines[3], lines[4]]) + "\n")
    out = tmp_path / "cal"
    res = run_cli(
        "calibrate",
        "--cv",
        "off",
        str(f),
        "--robot",
        "franka-fr3",
        "--model",
        "kinematic",
        "--no-report",
        "-q",
        "--out",
        str(out),
    )
    assert res.returncode == 0, res.stderr
    assert "2 rows repeat an earlier row" in res.stderr
    checks = json.loads((out / "report.json").read_text())["data_checks"]
    assert [(d["code"], d["rows"]) for d in checks] == [("duplicate_rows", [62, 63])]


@pytest.fixture(scope="module")
def sensor_model(tmp_path_factory) -> Path:
    """A model calibrated on simulated sensor data (experiment 1), saved."""
    from kinecal.simulation import experiment1

    e = experiment1(4, n_train=60, per_sphere=20)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = calibrate(FANUC, e.train, "kinematic")
    path = tmp_path_factory.mktemp("sensor") / "model.yaml"
    save_model(path, res.calibrated)
    return path


def test_issue_20_evaluate_refuses_tracker_points_with_a_sensor_model(
    tmp_path, run_cli, sensor_model, rng
):
    """Was: `RMS 2879 mm`, exit 0."""
    lim = FANUC.limits * 0.7
    q = rng.uniform(lim[:, 0], lim[:, 1], (20, 6))
    pts = Measurements("point", q, FANUC.fk_flange(q)[:, :3, 3] + [0.3, 0.0, 0.1])
    f = tmp_path / "points.csv"
    f.write_text(measurements_to_csv(pts, FANUC))
    res = run_cli("evaluate", str(f), "--model", str(sensor_model), "--json")
    _one_error_line(res, "tracker points", "calibrated on sensor data")


def test_issue_20_evaluate_pose_data_with_a_point_model_compares_positions(
    tmp_path, run_cli
):
    ur10e = load_robot("ur10e")
    from kinecal.io import read_measurements

    m = read_measurements(REAL / "ur10_mocap.csv", ur10e)
    points = Measurements("point", m.q_ctrl, m.p, rows=m.rows, source=m.source)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate(ur10e, points, "kinematic").calibrated
    save_model(tmp_path / "model.yaml", cal)
    res = run_cli(
        "evaluate",
        str(REAL / "ur10_mocap.csv"),
        "--model",
        str(tmp_path / "model.yaml"),
    )
    assert res.returncode == 0, res.stderr
    assert "only the positions are compared" in res.stderr
    assert "orient" not in res.stdout  # no meaningless orientation error


def test_issue_20_plan_refuses_a_model_of_another_robot(tmp_path, run_cli):
    fr3 = load_robot("franka-fr3")
    from kinecal.io import read_measurements

    m = read_measurements(REAL / "fr3_session_a.csv", fr3)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = calibrate(fr3, m, "kinematic").calibrated
    save_model(tmp_path / "model.yaml", cal)
    res = run_cli(
        "plan",
        "--robot",
        "ur10e",
        "--model",
        str(tmp_path / "model.yaml"),
        "--add",
        "5",
        "--out",
        str(tmp_path / "plan.csv"),
    )
    _one_error_line(res, "--robot ur10e", "calibrated for franka-fr3")


def test_issue_20_compensate_refuses_seeds_beyond_the_limits(
    tmp_path, run_cli, sensor_model
):
    rows = ["x_mm,y_mm,z_mm,j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg"]
    rows += ["400,0,300,0,10,-10,0,-60,0", "410,0,300,0,10,-10,0,-140,0"]  # J5: +-125
    f = tmp_path / "targets.csv"
    f.write_text("\n".join(rows) + "\n")
    res = run_cli(
        "compensate",
        str(f),
        "--model",
        str(sensor_model),
        "--out",
        str(tmp_path / "c.csv"),
    )
    _one_error_line(
        res, "line 3, column 'j5_deg': -140 is outside", "--allow-out-of-limits"
    )
    assert not np.any([p.name == "c.csv" for p in tmp_path.iterdir()])
