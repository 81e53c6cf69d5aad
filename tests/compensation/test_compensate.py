"""Compensation (issue 7): on the twin, through the CLI, and for unreachable targets."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinecal.compensation import compensate
from kinecal.identification import calibrate
from kinecal.io import save_model
from kinecal.models import solve_ik
from kinecal.simulation import LaserTracker, experiment2, planning_model
from tests.compensation.conftest import write_targets_csv


@pytest.fixture(scope="module")
def calibrated_twin():
    e = experiment2(41, tracker=LaserTracker(5e-6, 0.0))
    res = calibrate(e.truth.robot, e.train, "full")
    return e, res


def _targets(e, n, rng):
    goal = e.test.q_ctrl[rng.choice(e.test.n, n, replace=False)]
    p_target, _ = e.truth.evaluate(goal)
    seed = goal + np.radians(rng.normal(size=goal.shape) * 0.2)  # the program's joints
    return goal, p_target, seed


def test_issue_7_true_robot_reaches_compensated_targets(calibrated_twin, rng):
    e, res = calibrated_twin
    _, p_target, seed = _targets(e, 500, rng)
    out = compensate(res.calibrated, p_target, seed)
    assert out.ok.all()
    assert (
        out.error.max() < 1e-10
    )  # the calibrated model lands on the targets (1e-7 mm)
    reached, _ = e.truth.evaluate(out.q_ctrl)
    err = np.linalg.norm(reached - p_target, axis=1) * 1e3
    rms = float(np.sqrt(np.mean(err**2)))
    assert rms < 0.01, rms  # at the model's accuracy, well under 0.02 mm
    # Without compensation: nominal kinematics (with the set-up's frames) in the controller.
    pm, x = planning_model(e.truth)
    nominal = solve_ik(pm, x, p_target, seed)
    reached_nom, _ = e.truth.evaluate(nominal.q_ctrl)
    err_nom = np.linalg.norm(reached_nom - p_target, axis=1) * 1e3
    assert np.sqrt(np.mean(err_nom**2)) > 0.3  # hundreds of micrometres to millimetres
    assert np.sqrt(np.mean(err_nom**2)) > 30 * rms


def test_orientation_targets_and_limits(calibrated_twin, rng):
    e, res = calibrated_twin
    _, p_target, seed = _targets(e, 50, rng)
    R = res.model.evaluate(
        res.params, e.test.subset(np.arange(50)).model_inputs(), orientation=True
    ).R_user_cam
    out = compensate(res.calibrated, p_target, seed, R_target=R)
    assert out.ok.all()
    lim = e.truth.robot.limits
    assert np.all((out.q_ctrl >= lim[:, 0]) & (out.q_ctrl <= lim[:, 1]))
    far = p_target.copy()
    far[:5] += np.array([3.0, 0.0, 0.0])  # 3 m away: out of reach
    out2 = compensate(res.calibrated, far, seed)
    assert set(out2.status[:5]) <= {"unreachable", "joint_limit"}
    assert (out2.status[5:] == "ok").all()


def test_cli_round_trip_and_unreachable_rows(
    calibrated_twin, run_cli_compensate, tmp_path, rng
):
    e, res = calibrated_twin
    model = save_model(tmp_path / "model.yaml", res.calibrated)

    def compensate_cli(src, out, *extra):
        return run_cli_compensate(
            "compensate", str(tmp_path / src), "--model", str(model),
            "--out", str(tmp_path / out), *extra,
        )  # fmt: skip

    _, p_target, seed = _targets(e, 200, rng)
    write_targets_csv(tmp_path / "targets.csv", p_target, seed)
    r = compensate_cli("targets.csv", "corrected.csv", "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["ok"] == 200
    text = (tmp_path / "corrected.csv").read_text().splitlines()
    assert text[0].endswith("err_mm,status")
    vals = np.array([[float(v) for v in line.split(",")[:-1]] for line in text[1:]])
    q = np.radians(vals[:, 3:9])
    # Round trip: corrected joints through the calibrated model land on the targets.
    from kinecal.models import ModelInputs

    p = res.model.evaluate(res.params, ModelInputs.make(q)).p_user
    assert np.abs(p - p_target).max() * 1e3 < 1e-4
    assert np.all(vals[:, -1] < 1e-4)
    # Unreachable rows: per-row report, exit 4, nothing written ...
    bad = p_target.copy()
    bad[[3, 7]] += [5.0, 0, 0]
    write_targets_csv(tmp_path / "bad.csv", bad, seed)
    r = compensate_cli("bad.csv", "bad-out.csv")
    assert r.returncode == 4
    assert "line 5:" in r.stderr and "line 9:" in r.stderr
    assert not (tmp_path / "bad-out.csv").exists()
    # ... unless allowed, then flagged in the file.
    r = compensate_cli("bad.csv", "bad-out.csv", "--allow-unreachable")
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "bad-out.csv").read_text().splitlines()[1:]
    flags = [row.rsplit(",", 1)[1] for row in rows]
    assert flags[3] != "ok" and flags[7] != "ok" and flags.count("ok") == 198
    r = compensate_cli("targets.csv", "corrected.csv")
    assert r.returncode == 2 and "use --force" in r.stderr


@pytest.fixture
def run_cli_compensate():
    import subprocess
    import sys

    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "kinecal", *args],
            capture_output=True,
            text=True,
            timeout=300,
        )

    return run
