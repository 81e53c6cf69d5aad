"""The CLI workflow of DESIGN §11 on simulated data, as a user runs it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml


@pytest.fixture(scope="module")
def exp2_files(tmp_path_factory):
    import subprocess
    import sys

    d = tmp_path_factory.mktemp("exp2")
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "kinecal",
            "simulate",
            "--experiment",
            "2",
            "--out",
            str(d),
            "--seed",
            "5",
            "--noise-um",
            "5",
            "-q",
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    return d


def test_calibrate_then_evaluate(run_cli, exp2_files, tmp_path):
    out = tmp_path / "cal"
    res = run_cli(
        "calibrate",
        str(exp2_files / "train.csv"),
        "--robot",
        "fanuc-lrmate200id",
        "--model",
        "full",
        "--out",
        str(out),
        "-q",
    )
    assert res.returncode == 0, res.stderr
    for name in ("model.yaml", "report.json", "report.html", "manifest.json"):
        assert (out / name).is_file(), name
    assert "before" in res.stdout and "after" in res.stdout
    report = json.loads((out / "report.json").read_text())
    assert report["after"]["rms_mm"] < report["before"]["rms_mm"] / 20
    assert report["identifiability"]["unidentifiable"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert len(manifest["inputs"]["data"]["sha256"]) == 64
    from kinecal.models import compiled_kernel_available

    code = "c" if compiled_kernel_available() else "numpy"
    assert manifest["config"]["model_code"] == code  # which code computed the model
    res = run_cli(
        "evaluate",
        str(exp2_files / "test.csv"),
        "--model",
        str(out / "model.yaml"),
        "--json",
    )
    assert res.returncode == 0, res.stderr
    metrics = json.loads(res.stdout)
    assert set(metrics) == {"n", "rms_mm", "std_mm", "mean_mm", "max_mm"}
    assert metrics["n"] > 6500
    assert metrics["rms_mm"] < 0.012  # noise floor 0.0087 mm
    assert metrics["rms_mm"] ** 2 == pytest.approx(
        metrics["mean_mm"] ** 2 + metrics["std_mm"] ** 2
    )
    res = run_cli(
        "evaluate",
        str(exp2_files / "test.csv"),
        "--model",
        str(out / "model.yaml"),
        "--refit",
        "user",
        "--json",
        "--errors-out",
        str(tmp_path / "errors.csv"),
    )
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["rms_mm"] < 0.012
    assert (
        (tmp_path / "errors.csv").read_text().startswith("row,ex_mm,ey_mm,ez_mm,err_mm")
    )
    # Results are never overwritten silently.
    args = ["calibrate", str(exp2_files / "train.csv"), "--robot", "fanuc-lrmate200id",
            "--out", str(out), "-q"]  # fmt: skip
    again = run_cli(*args)
    assert again.returncode == 2 and "use --force" in again.stderr
    forced = run_cli(*args, "--force", "--model", "kinematic", "--no-report")
    assert forced.returncode == 0, forced.stderr
    assert (
        yaml.safe_load((out / "model.yaml").read_text())["model"]["name"] == "kinematic"
    )


def test_compare_prints_the_table(run_cli, exp2_files, tmp_path):
    res = run_cli(
        "compare",
        str(exp2_files / "train.csv"),
        str(exp2_files / "test.csv"),
        "--robot",
        "fanuc-lrmate200id",
        "--json",
        "-q",
        "--out",
        str(tmp_path / "cmp"),
    )
    assert res.returncode == 0, res.stderr
    rows = {r["model"]: r for r in json.loads(res.stdout)}
    assert list(rows) == ["nominal", "kinematic", "ntm", "rfcm", "full"]
    assert rows["full"]["size"] == 50 and rows["kinematic"]["size"] == 27
    assert rows["kinematic"]["rms_mm"] > rows["full"]["rms_mm"]
    assert (tmp_path / "cmp" / "report.html").is_file()
    assert (tmp_path / "cmp" / "model-full.yaml").is_file()


def test_sensor_experiment_workflow(run_cli, calibrated_exp1, tmp_path):
    d, out = calibrated_exp1  # simulate --experiment 1, calibrate with --targets
    res = run_cli(
        "evaluate",
        str(d / "test.csv"),
        "--model",
        str(out / "model.yaml"),
        "--targets",
        str(d / "targets.csv"),
        "--json",
    )
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["rms_mm"] < 0.03
    # Issue 19: a new session that sees two spheres is registered, with a warning that
    # the rotation about the line through them is undetermined (was a traceback).
    lines = (d / "test.csv").read_text().splitlines()
    col = lines[0].split(",").index("target")
    first_two = sorted({ln.split(",")[col] for ln in lines[1:]})[:2]
    two = tmp_path / "two.csv"
    two.write_text(
        "\n".join(
            [lines[0]] + [ln for ln in lines[1:] if ln.split(",")[col] in first_two]
        )
        + "\n"
    )
    res = run_cli(
        "evaluate",
        str(two),
        "--model",
        str(out / "model.yaml"),
        "--targets",
        str(d / "targets.csv"),
        "--refit",
        "user",
        "--json",
    )
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr and "not determined" in res.stderr
    assert json.loads(res.stdout)["rms_mm"] < 0.1
    res = run_cli(
        "calibrate",
        str(d / "train.csv"),
        "--robot",
        "fanuc-lrmate200id",
        "--out",
        str(tmp_path / "x"),
        "-q",
    )
    assert res.returncode == 2 and "needs a --targets file" in res.stderr


def test_same_seed_same_files(run_cli, exp2_files, tmp_path):
    for k in (1, 2):
        assert (
            run_cli(
                "simulate",
                "--experiment",
                "2",
                "--seed",
                "9",
                "--out",
                str(tmp_path / f"r{k}"),
                "-q",
                "--extras",
                "harmonics,thermal",
            ).returncode
            == 0
        )
    for name in ("train.csv", "test.csv", "truth.yaml"):
        assert (tmp_path / "r1" / name).read_bytes() == (
            tmp_path / "r2" / name
        ).read_bytes(), name
    # another seed (5, the module's simulation), other data
    assert (tmp_path / "r1" / "train.csv").read_bytes() != (
        exp2_files / "train.csv"
    ).read_bytes()


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (
            "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,x_mm,y_mm\n1,2,3,4,5,6,7,8\n",
            "missing column 'z_mm'",
        ),
        (
            "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,x_mm,y_mm,z_mm\n1,2,3,4,5,6,7,,9\n",
            "line 2, column 'y_mm'",
        ),
        ("", "the file is empty"),
        (
            "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,x_mm,y_mm,z_mm\n1,2,3,4,5,7,8,9\n",
            "has 6 joints",
        ),
    ],
)
def test_bad_data_exit_2_with_one_line(run_cli, tmp_path, content, match):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    res = run_cli(
        "calibrate",
        str(f),
        "--robot",
        "fanuc-lrmate200id",
        "--out",
        str(tmp_path / "o"),
    )
    assert res.returncode == 2
    assert match in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "model.yaml").exists()


def test_too_few_poses_is_a_clear_error(run_cli, exp2_files, tmp_path):
    lines = (exp2_files / "train.csv").read_text().splitlines()[:11]
    f = tmp_path / "ten.csv"
    f.write_text("\n".join(lines) + "\n")
    args = ["calibrate", str(f), "--robot", "fanuc-lrmate200id", "--out"]
    res = run_cli(*args, str(tmp_path / "o"), "--model", "full")
    assert res.returncode == 2
    assert (
        "10 poses give 30 residuals" in res.stderr and "measure at least" in res.stderr
    )
    # The default (auto) cross-validates: it says how many poses its folds need.
    res = run_cli(*args, str(tmp_path / "a"))
    assert res.returncode == 2
    assert "expected at least 13 poses" in res.stderr and "fixed --model" in res.stderr
    assert "Traceback" not in res.stderr


def test_demo_runs_both_experiments(run_cli, tmp_path):
    res = run_cli("demo", "--out", str(tmp_path / "demo"), "-q")
    assert res.returncode == 0, res.stderr
    out = res.stdout
    assert "experiment 2: laser tracker" in out and "experiment 1: 3D sensor" in out
    summary = json.loads((tmp_path / "demo" / "summary.json").read_text())
    for exp in ("1", "2"):
        table = {r["model"]: r["rms_mm"] for r in summary["experiments"][exp]["table"]}
        assert table["kinematic"] > table["full"]  # the paper's ordering
        assert table["full"] < 0.1  # tens of micrometres
        assert summary["experiments"][exp]["recovery"]["within_3_std"] >= 0.95
    assert min(summary["experiments"]["2"]["joint_ranges_deg"]) >= 50
    assert Path(tmp_path / "demo" / "experiment2" / "report.html").is_file()
    # Issue 21: the files the README promises (the truth among them).
    for exp in ("experiment1", "experiment2"):
        d = tmp_path / "demo" / exp
        names = {p.name for p in d.iterdir()}
        want = {"train.csv", "test.csv", "truth.yaml", "comparison.json", "report.html"}
        want |= {f"model-{m}.yaml" for m in ("kinematic", "ntm", "rfcm", "full")}
        assert want | {"figures"} <= names, (exp, names)
    assert (tmp_path / "demo" / "experiment1" / "targets.csv").is_file()
    assert summary["seconds"] < 60
    again = run_cli("demo", "--out", str(tmp_path / "demo"), "-q")
    assert again.returncode == 2 and "use --force" in again.stderr
