"""Tracker points exported in a left-handed frame (one axis negated): calibrate names
the mirror (exit 2) instead of blaming the robot file after a fit that ends far off
(before: 'the fit ends with parameter joint1.a ... another robot?', or a model file
written with errors of metres). Right-handed data are not affected."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.io import write_measurements
from kinecal.robot import load_robot
from kinecal.simulation import robot_experiment, robot_truth


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    robot = load_robot("fanuc-lrmate200id")
    exp = robot_experiment(robot_truth(robot, seed=2), 3, n_train=40, n_test=1)
    d = tmp_path_factory.mktemp("mirror")
    write_measurements(d / "right.csv", exp.train, robot)
    text = (d / "right.csv").read_text().splitlines()
    head = text[0].split(",")
    y = head.index("y_mm")
    rows = [r.split(",") for r in text[1:]]
    for r in rows:
        r[y] = repr(-float(r[y]))
    (d / "left.csv").write_text("\n".join([text[0]] + [",".join(r) for r in rows]))
    return d


@pytest.mark.parametrize("model", ["kinematic", "full"])
def test_a_left_handed_frame_is_named(twin, tmp_path, run_cli_here, model):
    out = tmp_path / "cal"
    res = run_cli_here(
        "calibrate", str(twin / "left.csv"), "--robot", "fanuc-lrmate200id",
        "--model", model, "--cv", "off", "--no-report", "-q", "--out", str(out),
    )  # fmt: skip
    assert res.returncode == 2, res.stdout + res.stderr
    assert "mirror image" in res.stderr and "left-handed" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (out / "model.yaml").exists()


def test_right_handed_data_calibrate(twin, tmp_path, run_cli_here):
    res = run_cli_here(
        "calibrate", str(twin / "right.csv"), "--robot", "fanuc-lrmate200id",
        "--model", "kinematic", "--cv", "off", "--no-report", "-q",
        "--out", str(tmp_path / "cal"),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "mirror" not in res.stderr
    assert np.isfinite(float(res.stdout.split("RMS")[1].split()[0]))
