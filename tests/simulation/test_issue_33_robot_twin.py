"""Issue 33: `kinecal simulate --robot`, a twin of any robot. Parameter recovery within
the reported uncertainty on three robots of different structure: a 6R industrial arm
(the lumped self-weight layout), a UR-type arm and a 7R arm (general link model from
URDF link masses), and the twin against an independent gravity computation."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from kinecal.identification import calibrate, evaluate
from kinecal.io import load_model, read_measurements
from kinecal.robot import load_robot, robot_from_urdf
from kinecal.simulation import (
    gravity_torques,
    parameter_recovery,
    robot_experiment,
    robot_truth,
)
from tests.independent_arm import ARM7, TORSO, UR6, random_poses, true_arm, urdf_text


def _urdf_robot(tmp_path, arm, name):
    path = tmp_path / f"{name}.urdf"
    path.write_text(urdf_text(arm, name))
    return robot_from_urdf(path, tip="flange")


@pytest.mark.parametrize("which", ["generic-6r", "ur6", "arm7"])
def test_parameter_recovery(which, tmp_path):
    arms = {"ur6": UR6, "arm7": ARM7}
    robot = (
        load_robot(which)
        if which not in arms
        else _urdf_robot(tmp_path, arms[which], which)
    )
    truth = robot_truth(robot, seed=1)
    exp = robot_experiment(truth, 1, n_train=80, n_test=200)
    res = calibrate(robot, exp.train, "full")
    assert res.success
    rec = parameter_recovery(res, truth, exp.train)
    assert rec.max_abs_z < 4.0, (
        rec.names[int(np.nanargmax(np.abs(rec.z)))],
        rec.max_abs_z,
    )
    assert rec.fraction_within(2.0) >= 0.9
    full = evaluate(res.calibrated, exp.test).metrics.rms_mm
    kin = evaluate(calibrate(robot, exp.train, "kinematic").calibrated, exp.test)
    assert full < 0.045  # the tracker's noise is ~0.02 mm
    assert kin.metrics.rms_mm > 2 * full  # the twin's compliance is there


def test_twin_gravity_torques_match_independent(tmp_path):
    """The twin's torque per unit weight (1 kg reference, no tool) against the
    independent simulator's for the torso robot (a prismatic first joint)."""
    robot = _urdf_robot(tmp_path, TORSO, "torso")
    q = random_poses(20, np.random.default_rng(0), TORSO)
    ind = true_arm(0, arm=TORSO, exact=True).gravity_torques(q) / 9.80665
    tool = gravity_torques(replace(robot, link_masses=()), q)
    np.testing.assert_allclose(gravity_torques(robot, q) - tool, ind, atol=1e-12)


def test_simulate_robot_cli(tmp_path, capsys):
    from kinecal.cli import main

    urdf = tmp_path / "ur6.urdf"
    urdf.write_text(urdf_text(UR6, "ur6"))
    out = tmp_path / "twin"
    code = main(
        [
            "simulate",
            "--robot",
            str(urdf),
            "--out",
            str(out),
            "--n-train",
            "40",
            "--n-test",
            "50",
            "--payload-kg",
            "2",
            "-q",
        ]
    )
    text = capsys.readouterr()
    assert code == 0, text.err
    assert sorted(p.name for p in out.iterdir()) == [
        "manifest.json",
        "robot.yaml",
        "test.csv",
        "train.csv",
        "truth.yaml",
    ]
    robot = load_robot(out / "robot.yaml")
    assert robot.link_bodies == (2, 3, 4, 5, 6) and robot.payload_kg == 2
    train = read_measurements(out / "train.csv", robot)
    assert train.n == 40 and np.all(train.payload_kg == 2)
    # The truth's compliance is per unit of the simulated payload, written as its
    # reference payload (evaluate refuses payload data against a model without one).
    assert load_model(out / "truth.yaml").reference_payload_kg == 2
    code = main(
        [
            "evaluate",
            str(out / "test.csv"),
            "--model",
            str(out / "truth.yaml"),
            "--json",
        ]
    )
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["rms_mm"] < 0.04  # the truth sees only the noise
    # A plan's poses become train.csv; --experiment and --robot do not mix.
    (tmp_path / "plan.csv").write_text(
        "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg\n"
        "10,-40,30,20,10,5\n-60,-120,-50,90,-70,100\n120,-20,100,-80,60,-150\n"
    )
    code = main(
        [
            "simulate",
            "--robot",
            str(urdf),
            "--out",
            str(tmp_path / "t2"),
            "--plan",
            str(tmp_path / "plan.csv"),
            "-q",
        ]
    )
    capsys.readouterr()
    assert code == 0
    assert read_measurements(tmp_path / "t2" / "train.csv", robot).n == 3
    code = main(
        [
            "simulate",
            "--robot",
            str(urdf),
            "--experiment",
            "1",
            "--out",
            str(tmp_path / "t3"),
        ]
    )
    assert code != 0 and "--robot" in capsys.readouterr().err
