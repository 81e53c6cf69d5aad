"""``kinecal plan`` as a user runs it (DESIGN §11, issue 22)."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from kinecal.identification import calibrate
from kinecal.io import save_model, write_json, write_measurements
from kinecal.simulation import LaserTracker, experiment2

ROBOT = "fanuc-lrmate200id"


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


def rows_of(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="") as f:
        data = list(csv.reader(f))
    return data[0], data[1:]


@pytest.fixture(scope="module")
def twin_files(tmp_path_factory):
    """A CAND.csv of 1500 experiment-2 poses (with an extra column the plan keeps), the
    20 poses measured first and a calibration from them (model.yaml, report.json)."""
    d = tmp_path_factory.mktemp("plan")
    e = experiment2(4, tracker=LaserTracker(5e-6, 0.0))
    rng = np.random.default_rng(4)
    pick = rng.choice(e.test.n, 1500, replace=False)
    q = np.degrees(e.test.q_ctrl[pick])
    lines = ["j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,label"]
    lines += [",".join(f"{v:.5f}" for v in r) + f",p{k}" for k, r in enumerate(q)]
    (d / "cand.csv").write_text("\n".join(lines) + "\n")
    first = e.train.subset(np.arange(20))
    write_measurements(d / "first.csv", first, e.truth.robot)
    res = calibrate(e.truth.robot, first, "full")
    save_model(d / "cal" / "model.yaml", res.calibrated)
    write_json(d / "cal" / "report.json", {"noise_sigma_mm": 0.005})
    return d


def test_plan_writes_chosen_candidate_rows_and_a_report(run_cli, twin_files, tmp_path):
    cand = twin_files / "cand.csv"
    out = tmp_path / "PLAN.csv"
    args = ["plan", "--robot", ROBOT, "--candidates", str(cand), "--poses", "20"]
    args += ["--out", str(out), "--noise-mm", "0.005", "--tool", "44,-60,104", "-q"]
    res = run_cli(*args)
    assert res.returncode == 0, res.stderr
    head_c, rows_c = rows_of(cand)
    head_p, rows_p = rows_of(out)
    assert head_p == head_c
    assert len(rows_p) == 20 and len({tuple(r) for r in rows_p}) == 20
    assert all(r in rows_c for r in rows_p)  # the same values, verbatim
    rep = json.loads((tmp_path / "PLAN.report.json").read_text())
    assert rep["n_poses"] == 20 and rep["candidates"]["n"] == 1500
    assert [rows_c[i - 2] for i in rep["order"]["candidate_rows"]] == rows_p
    assert rep["predicted"]["ratio"] < rep["random"]["ratio"]
    assert rep["predicted"]["floor_mm"] == pytest.approx(0.005 * np.sqrt(3))
    names = {p["name"] for p in rep["parameters"]}
    assert "joint2.a" in names and "joint1.k0" not in names
    assert "joint1.k0" in rep["design"]["not_determined"]
    assert rep["order"]["path_deg"] < rep["order"]["path_unordered_deg"]
    assert "predicted" in res.stdout or res.stdout == ""
    # never overwrite without --force
    again = run_cli(*args)
    assert again.returncode == 2 and "exists; use --force" in again.stderr
    assert run_cli(*args, "--force", "--json").returncode == 0


def test_plan_json_summary(run_cli, twin_files, tmp_path):
    res = run_cli(
        "plan", "--robot", ROBOT, "--candidates", str(twin_files / "cand.csv"),
        "--poses", "25", "--model", "kinematic", "--criterion", "D",
        "--out", str(tmp_path / "p.csv"), "--report", str(tmp_path / "r.json"),
        "--json", "-q",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = json.loads(res.stdout)
    assert doc["n_poses"] == 25 and doc["report"] == str(tmp_path / "r.json")
    assert json.loads((tmp_path / "r.json").read_text())["criterion"] == "D"


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("j1_deg,j2_deg\n0,0\n", "needs j1_deg .. j6_deg"),
        (
            "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg\n0,0,0,0,30,0\n0,150,0,0,30,0\n",
            "line 3, column 'j2_deg': 150 is outside the joint limits [-100, 145]",
        ),
        (
            "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg\n0,0,x,0,30,0\n",
            "line 2, column 'j3_deg': expected a number",
        ),
    ],
)
def test_bad_candidates_give_one_line_errors(run_cli, tmp_path, content, message):
    cand = tmp_path / "c.csv"
    cand.write_text(content)
    res = run_cli(
        "plan", "--robot", ROBOT, "--candidates", str(cand), "--poses", "1",
        "--out", str(tmp_path / "p.csv"),
    )  # fmt: skip
    assert res.returncode == 2
    assert message in res.stderr and str(cand) in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "p.csv").exists()


def test_bad_options_are_refused(run_cli, twin_files, tmp_path):
    base = ["plan", "--robot", ROBOT, "--candidates", str(twin_files / "cand.csv")]
    out = ["--out", str(tmp_path / "p.csv")]
    res = run_cli(*base, "--poses", "1501", *out)
    assert res.returncode == 2 and "1501 poses asked, but there are 1500" in res.stderr
    res = run_cli(*base, "--poses", "5", "--model", "nonsense", *out)
    assert res.returncode == 2 and "kinematic, ntm, rfcm, full or a model.yaml" in (
        res.stderr.replace(" or", ", or")
        .replace(", , or", ", or")
        .replace(", or", " or")
    )
    res = run_cli(*base, *out)
    assert res.returncode == 2 and "give --poses N" in res.stderr
    res = run_cli(*base, "--poses", "5", "--instrument", "sensor", *out)
    assert res.returncode == 2 and "needs --targets" in res.stderr


def test_generated_candidates_for_a_tracker(run_cli, tmp_path):
    res = run_cli(
        "plan", "--robot", ROBOT, "--poses", "15", "--model", "kinematic",
        "--joint-range", "J1:-60:60,J2:-30:60", "--n-candidates", "400",
        "--tool", "0,50,100", "--save-candidates", str(tmp_path / "c.csv"),
        "--out", str(tmp_path / "p.csv"), "-q",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    head, cand = rows_of(tmp_path / "c.csv")
    head_p, plan = rows_of(tmp_path / "p.csv")
    assert head == head_p == [f"j{k}_deg" for k in range(1, 7)]
    assert len(cand) == 400 and len(plan) == 15 and all(r in cand for r in plan)
    q = np.array(cand, float)
    assert q[:, 0].min() >= -60 and q[:, 0].max() <= 60
    assert q[:, 1].min() >= -30 and q[:, 1].max() <= 60
    assert np.abs(q[:, 4]).min() >= 10


def test_generated_sensor_views_of_targets(run_cli, tmp_path):
    t = tmp_path / "targets.csv"
    t.write_text("target,x_mm,y_mm,z_mm\nS1,500,150,0\nS2,500,-150,0\nS3,400,0,-100\n")
    res = run_cli(
        "plan", "--robot", ROBOT, "--poses", "20", "--instrument", "sensor",
        "--targets", str(t), "--n-candidates", "60", "--noise-mm", "0.006",
        "--out", str(tmp_path / "p.csv"), "-q",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    head, plan = rows_of(tmp_path / "p.csv")
    assert head[-1] == "target" and len(plan) == 20
    assert {r[-1] for r in plan} <= {"S1", "S2", "S3"}
    rep = json.loads((tmp_path / "p.report.json").read_text())
    assert rep["instrument"] == "sensor" and rep["candidates"]["source"] == "generated"


def test_sequential_plan_adds_poses_to_a_calibration(run_cli, twin_files, tmp_path):
    model = twin_files / "cal" / "model.yaml"
    res = run_cli(
        "plan", "--model", str(model), "--add", "8", "--candidates",
        str(twin_files / "cand.csv"), "--data", str(twin_files / "first.csv"),
        "--out", str(tmp_path / "add.csv"),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "0.005 mm per axis from" in res.stderr  # the calibration's noise
    rep = json.loads((tmp_path / "add.report.json").read_text())
    assert rep["sequential"]["data"].endswith("first.csv")
    assert rep["predicted"]["ratio"] < rep["random"]["ratio"] < rep["before"]["ratio"]
    assert len(rows_of(tmp_path / "add.csv")[1]) == 8
    res = run_cli(
        "plan", "--model", str(model), "--poses", "8",
        "--candidates", str(twin_files / "cand.csv"), "--out", str(tmp_path / "x.csv"),
    )  # fmt: skip
    assert res.returncode == 2 and "--add N" in res.stderr


def test_sequential_plan_checks_the_measurements_of_its_data(
    run_cli, twin_files, tmp_path
):
    """--data with measurement columns is read as measurements (a text cell in z_mm was
    accepted: only the joints were read); a file of joints alone is still a pose list."""
    model = twin_files / "cal" / "model.yaml"
    lines = (twin_files / "first.csv").read_text().splitlines()
    head = lines[0].split(",")
    z = head.index("z_mm")
    row = lines[3].split(",")
    row[z] = "abc"
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join([lines[0], *lines[1:3], ",".join(row), *lines[4:]]) + "\n")
    base = ["plan", "--model", str(model), "--add", "4", "--candidates"]
    base += [str(twin_files / "cand.csv"), "-q"]
    res = run_cli(*base, "--data", str(bad), "--out", str(tmp_path / "a.csv"))
    assert res.returncode != 0 and not (tmp_path / "a.csv").exists()
    last = res.stderr.strip().splitlines()[-1]
    assert "bad.csv" in last and "line 4" in last and "z_mm" in last, res.stderr
    joints = tmp_path / "joints.csv"
    jcols = [i for i, h in enumerate(head) if h.endswith("_deg") and h[0] == "j"]
    joints.write_text(
        "\n".join(",".join(r.split(",")[i] for i in jcols) for r in lines) + "\n"
    )
    res = run_cli(*base, "--data", str(joints), "--out", str(tmp_path / "b.csv"))
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize(
    "args, says",
    [
        (("--poses", "14"), "42 residuals for the 50 parameters of the 'full' model"),
        (("--poses", "5", "--model", "kinematic"), "expected at least"),
        (("--poses", "50", "--tool", "1e9,0,0"), "1e+09 mm away; expected mm"),
        (("--poses", "50", "--user-frame", "2e6,0,0,0,0,0"), "at most 100 m"),
    ],
)
def test_a_plan_that_cannot_be_right_is_refused_and_writes_nothing(
    run_cli, tmp_path, args, says
):
    """Too few poses for any calibration of the model (a first plan, nothing measured
    before), or a tool or frame given in the wrong units: exit 2 with what is expected,
    no plan written (it ended in an unclear "no acceptable candidate" or exited 0)."""
    out = tmp_path / "plan.csv"
    res = run_cli(
        "plan", "--robot", ROBOT, "--n-candidates", "300", *args, "--out", out
    )
    assert res.returncode == 2, res.stderr
    assert says in res.stderr
    assert list(tmp_path.iterdir()) == []
