"""Issue 33: a 3D-sensor twin of any robot (`kinecal simulate --robot R --sensor`), so the
sensor pipeline can be rehearsed on a robot other than the LR Mate 200iD. Parameter
recovery within the reported uncertainty on a UR-type arm imported from an independent
URDF; the views are those of experiment 1 (the working distance, from above); the CLI
writes the FANUC sensor twin's files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from kinecal.geometry import transform_to_euler
from kinecal.identification import calibrate, evaluate
from kinecal.io import read_measurements, read_targets
from kinecal.robot import load_robot, robot_from_urdf
from kinecal.simulation import (
    SENSOR_MOUNT_MM,
    noise_free,
    parameter_recovery,
    robot_sensor_experiment,
    robot_sensor_truth,
)
from tests.independent_arm import ARM7, UR6, urdf_text


@pytest.fixture(scope="module")
def ur6(tmp_path_factory):
    path = tmp_path_factory.mktemp("ur6") / "ur6.urdf"
    path.write_text(urdf_text(UR6, "ur6"))
    return robot_from_urdf(path, tip="flange")


def test_sensor_twin_parameter_recovery(ur6):
    truth, spheres = robot_sensor_truth(ur6, seed=3)
    exp = robot_sensor_experiment(truth, spheres, 3, n_train=100, n_test=100)
    assert exp.train.kind == "sensor" and exp.train.n == 100 and exp.test.n == 100
    # The nominal mount is the robot file's tool; the true one is off it.
    mount = transform_to_euler(truth.robot.T_flange_tool) * 1e3
    np.testing.assert_allclose(mount, [*SENSOR_MOUNT_MM, 0, 0, 0], atol=1e-9)
    idx = truth.model.cam_index[0]
    dev = truth.params[idx] - truth.model.nominal[idx]
    dev[3:] = (dev[3:] + np.pi) % (2 * np.pi) - np.pi
    assert 5e-5 < np.linalg.norm(dev[:3]) < 5e-3  # m
    assert 1e-4 < np.linalg.norm(dev[3:]) < 0.03  # rad
    res = calibrate(truth.robot, exp.train, "full")
    assert res.success
    rec = parameter_recovery(res, truth, exp.train)
    worst = rec.names[int(np.nanargmax(np.abs(rec.z)))]
    assert rec.max_abs_z < 4.0, (worst, rec.max_abs_z)
    assert rec.fraction_within(2.0) >= 0.9
    names = set(rec.names)
    assert {"cam.x", "cam.w", "base.r", "joint2.lambda", "link3.m"} <= names
    full = evaluate(res.calibrated, exp.test).metrics.rms_mm
    kin = evaluate(calibrate(truth.robot, exp.train, "kinematic").calibrated, exp.test)
    assert full < 0.03  # the sensor's noise is 4-8 um
    assert kin.metrics.rms_mm > 3 * full  # the twin's compliance is there


@pytest.mark.parametrize(
    "which", ["generic-6r", pytest.param("arm7", marks=pytest.mark.slow)]
)
def test_sensor_twin_recovery_other_structures(which, tmp_path):
    """A 6R industrial arm (lumped self-weight layout) and a 7R arm (general link model
    from its URDF's masses)."""
    if which == "arm7":
        (tmp_path / "arm7.urdf").write_text(urdf_text(ARM7, "arm7"))
        robot = robot_from_urdf(tmp_path / "arm7.urdf", tip="flange")
    else:
        robot = load_robot(which)
    truth, spheres = robot_sensor_truth(robot, seed=1)
    exp = robot_sensor_experiment(truth, spheres, 1, n_train=80, n_test=1)
    res = calibrate(truth.robot, exp.train, "full")
    rec = parameter_recovery(res, truth, exp.train)
    assert res.success and rec.max_abs_z < 4.0 and rec.fraction_within(2.0) >= 0.9


def test_sensor_twin_views(ur6):
    """Each pose sees its sphere at the sensor's working distance, near its optical
    axis, from above (elevation >= 25 deg); the spheres sit on a plate."""
    truth, spheres = robot_sensor_truth(ur6, seed=0)
    exp = robot_sensor_experiment(truth, spheres, 0, n_train=60, n_test=60)
    q = np.concatenate([exp.train.q_ctrl, exp.test.q_ctrl])
    ti = np.concatenate([exp.train.target_index, exp.test.target_index])
    assert np.bincount(ti).min() >= 25  # every sphere seen from many poses
    p = noise_free(truth, exp.train).p
    dist = np.linalg.norm(p, axis=1)
    assert np.all((dist > 0.11) & (dist < 0.14))
    assert np.all(np.linalg.norm(p[:, :2], axis=1) < 0.01)  # near the optical axis
    # From above: the optical axis points down, in the robot base frame.
    _, R = truth.evaluate(q, orientation=True)
    R_b = truth.model.base_frames(truth.params)[0][0]
    z_base = np.einsum("ij,ni->nj", R_b, R[:, :, 2])
    assert np.all(z_base[:, 2] < -np.sin(np.radians(24.0)))
    # The plate: the sphere centres within a few cm of one height, tens of cm apart.
    c_base = (spheres - truth.model.base_frames(truth.params)[1][0]) @ R_b
    assert np.ptp(c_base[:, 2]) < 0.1
    gaps = np.linalg.norm(c_base[:, None] - c_base[None], axis=2)
    assert gaps[np.triu_indices(4, 1)].min() > 0.1
    assert np.all(np.diff(q[:, 0]) != 0)  # no repeated pose


def test_simulate_robot_sensor_cli(tmp_path, run_cli_here):
    urdf = tmp_path / "ur6.urdf"
    urdf.write_text(urdf_text(UR6, "ur6"))
    out = tmp_path / "twin"
    args = ["simulate", "--robot", urdf, "--sensor", "--out", out]
    r = run_cli_here(*args, "--n-train", "40", "--n-test", "30", "-q")
    assert r.returncode == 0, r.stderr
    assert "--targets" in r.stdout
    assert sorted(p.name for p in out.iterdir()) == [
        "manifest.json",
        "robot.yaml",
        "targets.csv",
        "test.csv",
        "train.csv",
        "truth.yaml",
    ]
    robot = load_robot(out / "robot.yaml")
    np.testing.assert_allclose(robot.T_flange_tool[:3, 3] * 1e3, SENSOR_MOUNT_MM)
    targets = str(out / "targets.csv")
    tg = read_targets(targets)
    assert tg.labels == ("S1", "S2", "S3", "S4") and np.allclose(tg.radius, 15e-3)
    train = read_measurements(out / "train.csv", robot, targets)
    assert train.kind == "sensor" and train.n == 40
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["config"]["instrument"] == "sensor"
    r = run_cli_here(
        "evaluate", out / "test.csv", "--model", out / "truth.yaml",
        "--targets", targets, "--json",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["rms_mm"] < 0.02  # the truth sees only the noise
    # --sensor belongs to --robot; a sensor plans its own views.
    r = run_cli_here("simulate", "--sensor", "--out", tmp_path / "t2")
    assert r.returncode != 0 and "--sensor" in r.stderr
    plan = tmp_path / "plan.csv"
    plan.write_text("j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg\n10,-40,30,20,10,5\n")
    r = run_cli_here(*args[:4], "--plan", plan, "--out", tmp_path / "t3")
    assert r.returncode != 0 and "--plan" in r.stderr
    assert not (tmp_path / "t3").exists()


def test_sensor_twin_of_an_arm_that_cannot_look_down(tmp_path, run_cli_here):
    robot = tmp_path / "r2.yaml"
    robot.write_text(
        "name: r2\nconvention: dh\nunits: {length: mm, angle: deg}\njoints:\n"
        "  - {theta_offset: 0, d: 300, a: 0, alpha: 0, limits: [-170, 170]}\n"
        "  - {theta_offset: 0, d: 0, a: 300, alpha: 0, limits: [-170, 170]}\n"
    )
    r = run_cli_here("simulate", "--robot", robot, "--sensor", "--out", tmp_path / "o")
    assert r.returncode != 0 and "point its tool (--tool) down" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "o").exists()
