"""Issue 35 (2, 4): kinds of data checked where they meet (tracker data given with
--targets, a model on another robot's data, a simulated truth read back by evaluate
and plan), and per-row weights checked against the others."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.io import read_data
from kinecal.robot import load_robot
from tests.cli_contract import failed_with, run_kinecal

ROBOT = "fanuc-lrmate200id"


def _with_sigma(src, dst, sigma, row=3):
    rows = list(csv.reader(src.open()))
    k = rows[0].index("sigma_mm")
    rows[row][k] = sigma
    with dst.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    return dst


def test_issue_35_tracker_data_with_targets_is_refused(data, capsys, tmp_path):
    res = run_kinecal(
        capsys, "calibrate", "--cv", "off", data["train"], "--robot", ROBOT, "--model", "kinematic",
        "--targets", data["dir"] / "spheres.csv", "--out", tmp_path / "o", "-q",
    )  # fmt: skip
    failed_with(res, "train.csv", "point data", "spheres.csv", "no --targets")
    res = run_kinecal(
        capsys, "evaluate", data["test"], "--model", data["model"],
        "--targets", data["dir"] / "spheres.csv",
    )  # fmt: skip
    failed_with(res, "test.csv", "point data", "no --targets")


def test_issue_35_a_row_claiming_far_less_noise_is_refused(data, tmp_path):
    f = _with_sigma(data["train"], tmp_path / "w.csv", "1e-12")
    with pytest.raises(DataError) as e:
        read_data(f, load_robot(ROBOT))
    msg = str(e.value)
    for n in ("w.csv", "line 4", "'sigma_mm'", "1e-12", "median 0.005", "alone"):
        assert n in msg, msg


def test_issue_35_weights_within_a_factor_1000_are_kept(data, tmp_path):
    f = _with_sigma(data["train"], tmp_path / "w.csv", "0.00001")  # 1/500 of 0.005
    meas, _ = read_data(f, load_robot(ROBOT))
    assert meas.sigma[2] == pytest.approx(1e-8)


def test_issue_35_one_sigma_row_among_others_in_calibrate(data, capsys, tmp_path):
    f = _with_sigma(data["train"], tmp_path / "w.csv", "1e-12")
    res = run_kinecal(
        capsys, "calibrate", "--cv", "off", f, "--robot", ROBOT, "--model", "kinematic",
        "--out", tmp_path / "o", "-q",
    )  # fmt: skip
    failed_with(res, "w.csv", "line 4", "sigma_mm")
    assert not (tmp_path / "o").exists()


def test_issue_35_a_model_on_another_robots_data_is_refused(data, capsys, tmp_path):
    """Measurements of the long-arm LR Mate (7L) evaluated with the LR Mate's model."""
    a, b = load_robot(ROBOT), load_robot("fanuc-lrmate200id-7l")
    rows = list(csv.reader(data["test"].open()))
    head = rows[0]
    jk = [head.index(f"j{k}_deg") for k in range(1, 7)]
    xk = [head.index(c) for c in ("x_mm", "y_mm", "z_mm")]
    q = np.radians([[float(r[k]) for k in jk] for r in rows[1:]])
    shift = (b.fk_tool(q)[:, :3, 3] - a.fk_tool(q)[:, :3, 3]) * 1e3
    for r, s in zip(rows[1:], shift):
        for k, v in zip(xk, s):
            r[k] = f"{float(r[k]) + v:.6f}"
    f = tmp_path / "other.csv"
    with f.open("w", newline="") as fh:
        csv.writer(fh).writerows(rows)
    res = run_kinecal(capsys, "evaluate", f, "--model", data["model"])
    failed_with(res, "other.csv", "median error", "fanuc-lrmate200id", "model.yaml")
    res = run_kinecal(capsys, "evaluate", data["test"], "--model", data["model"])
    assert res.code == 0, res  # its own robot's data


def test_issue_35_simulated_truth_reads_back(capsys, tmp_path):
    """simulate's truth.yaml is a model of the data kind it generated: evaluate takes
    it on the sensor experiment's test set (it was refused as 'calibrated on poses')."""
    d = tmp_path / "exp1"
    res = run_kinecal(
        capsys, "simulate", "--experiment", "1", "--n-train", "30", "--out", d, "-q"
    )
    assert res.code == 0, res
    res = run_kinecal(
        capsys, "evaluate", d / "test.csv", "--model", d / "truth.yaml",
        "--targets", d / "targets.csv",
    )  # fmt: skip
    assert res.code == 0, res
    assert "RMS" in res.out


def _with_markers(src, dst, labels):
    rows = list(csv.reader(src.open()))
    rows[0].append("marker")
    for k, r in enumerate(rows[1:]):
        r.append(labels[k % len(labels)])
    with dst.open("w", newline="") as f:
        csv.writer(f).writerows(rows)
    return dst


def test_issue_35_several_markers_onto_a_model_of_one(data, capsys, tmp_path):
    """A model with one unnamed marker took any marker labels, all as one point."""
    f = _with_markers(data["test"], tmp_path / "m.csv", ["A", "B"])
    res = run_kinecal(capsys, "evaluate", f, "--model", data["model"])
    failed_with(
        res, "m.csv", "markers 'A', 'B'", "the model has one marker:", "own point"
    )
    f = _with_markers(data["test"], tmp_path / "one.csv", ["A"])
    res = run_kinecal(capsys, "evaluate", f, "--model", data["model"])
    assert res.code == 0, res  # one marker, named where the model's is not: the same


def test_issue_35_plan_with_targets_for_a_tracker(data, capsys, tmp_path):
    res = run_kinecal(
        capsys, "plan", "--robot", ROBOT, "--model", "kinematic", "--poses", "12",
        "--n-candidates", "60", "--targets", data["dir"] / "spheres.csv",
        "--out", tmp_path / "p.csv", "-q",
    )  # fmt: skip
    failed_with(res, "--targets", "--instrument tracker", "remove --targets")
    assert not (tmp_path / "p.csv").exists()
