"""The benchmarks' helpers run (the benchmarks themselves are `make bench`, not tests)."""

from __future__ import annotations

import dataclasses
import json
import os

import numpy as np
import pytest
from benchmarks._common import _median_time, _model_code

from kinecal.identification import Weights, calibrate, residuals
from kinecal.io import measurements_to_csv
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.simulation import LaserTracker, experiment2


def test_the_whole_process_scipy_baseline_fits_the_poses(tmp_path):
    """benchmarks._scipy_fd reads the poses from CSV and fits the model from the given
    start with scipy: the fit brings the residuals from millimetres to the noise."""
    from benchmarks import _scipy_fd

    e = experiment2(5, n_train=40, n_side=4, tracker=LaserTracker(5e-6, 0.0))
    robot = e.truth.robot
    cal = calibrate(robot, e.train, "kinematic")
    model = CalibrationModel(robot, ModelSpec.preset("kinematic", cam_rotation=False))
    free = np.array([s == "estimated" for s in cal.calibrated.status])
    x0, w = cal.registered, Weights(np.full(e.train.n, 5e-6))
    csv = tmp_path / "poses.csv"
    csv.write_text(measurements_to_csv(e.train, robot))
    case = tmp_path / "case.npz"
    spec = json.dumps(dataclasses.asdict(model.spec))
    np.savez(
        case, spec=spec, robot=robot.name, x0=x0, free=free, sigma=w.sigma, payload=0.0
    )
    assert _scipy_fd.main([str(case), str(csv), str(tmp_path / "x.npy")]) == 0
    x = np.load(tmp_path / "x.npy")

    def rms(p):
        return float(np.sqrt(np.mean(residuals(model, p, e.train, w).r ** 2)))

    assert rms(x0) > 50 and rms(x) < 3  # in noise sigmas


def test_timing_and_code_switch_helpers(monkeypatch):
    monkeypatch.delenv("KINECAL_KERNEL", raising=False)
    calls = []
    t, out = _median_time(lambda: calls.append(1) or len(calls), 5)
    assert len(calls) == 5 and out == 5 and 0 <= t.best <= t
    with _model_code("numpy"):
        assert os.environ["KINECAL_KERNEL"] == "numpy"
    assert "KINECAL_KERNEL" not in os.environ
    monkeypatch.setenv("KINECAL_KERNEL", "c")
    with _model_code("numpy"):
        pass
    assert os.environ["KINECAL_KERNEL"] == "c"


def test_the_instruction_count_helper_evaluates_the_model(tmp_path):
    from benchmarks import _instructions

    model = CalibrationModel(
        experiment2(5, n_train=10, n_side=3).truth.robot, ModelSpec.preset("full")
    )
    q = np.random.default_rng(0).uniform(-1, 1, size=(20, 6))
    path = tmp_path / "case.npz"
    np.savez(
        path,
        spec=json.dumps(dataclasses.asdict(model.spec)),
        robot=model.robot.name,
        params=model.nominal,
        q_ctrl=q,
        p_cam=np.zeros((20, 3)),
        load_scale=np.ones(20),
    )
    assert _instructions.main([str(path), "2"]) == 0


def test_the_issue_36_helpers():
    """The import-time parser sums self times by top package; the JᵀJ floor counts one
    triangle of the symmetric product; the per-pass blocks of poses hold every row."""
    from benchmarks._issue36 import _pass_blocks, import_times, jtj_floor_seconds

    text = (
        "import time: self [us] | cumulative | imported package\n"
        "import time:      1000 |       1000 |   numpy._core\n"
        "import time:       500 |       1500 | numpy\n"
        "import time:      2000 |       2000 | kinecal.models._spec\n"
        "import time:       300 |        300 | json\n"
        "not an import line\n"
    )
    t = import_times(text)
    assert t["numpy"] == pytest.approx(1.5e-3) and t["kinecal"] == pytest.approx(2e-3)
    assert t["total"] == pytest.approx(3.8e-3) and t["yaml"] == 0.0
    assert jtj_floor_seconds(6000, 50, 1e9) == pytest.approx(6000 * 50 * 51 / 1e9)
    X = np.random.default_rng(0).standard_normal((4, 3 * 7))
    blocks = _pass_blocks(X, poses=3)  # 3 + 3 + 1 poses
    assert [b.shape for b in blocks] == [(9, 4), (9, 4), (3, 4)]
    assert np.allclose(sum(b.T @ b for b in blocks), X @ X.T, rtol=1e-13, atol=0)
