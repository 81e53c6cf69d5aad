"""A robot whose first joint slides (a mobile manipulator's torso lift, as the TIAGo's):
every model and ``--model auto`` calibrate it, the transmission series go on its first
revolute joints, and a series asked for on the slide is refused by name."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.identification import (
    CalibrationOptions,
    calibrate,
    candidate_specs,
    evaluate,
    select_model,
    spec_for,
)
from kinecal.measurement._measurements import Measurements
from kinecal.robot import robot_from_dict
from kinecal.simulation import random_truth

LIFT = robot_from_dict(
    {
        "name": "lift-6r",
        "convention": "dh",
        "units": {"length": "mm", "angle": "deg"},
        "rated_payload_kg": 3.0,
        "joints": [
            {
                "theta_offset": 0,
                "d": 600,
                "a": 150,
                "alpha": 0,
                "type": "prismatic",
                "limits": [0, 350],
            },
            {"theta_offset": 0, "d": 300, "a": 0, "alpha": 90},
            {"theta_offset": 0, "d": 0, "a": 310, "alpha": 0},
            {"theta_offset": 90, "d": 0, "a": 0, "alpha": 90},
            {"theta_offset": 0, "d": 320, "a": 0, "alpha": -90},
            {"theta_offset": 0, "d": 0, "a": 0, "alpha": 90},
            {"theta_offset": 0, "d": 150, "a": 0, "alpha": 0},
        ],
    }
)


TRUTH = random_truth(LIFT, seed=5)


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


def _points(n: int, seed: int) -> tuple[Measurements, object]:
    truth = TRUTH
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.0, 2.0, (n, LIFT.n_joints))  # [rad]
    q[:, 0] = rng.uniform(0.02, 0.33, n)  # the slide [m]
    p, _ = truth.evaluate(q)
    return Measurements("point", q, p + rng.normal(size=p.shape) * 10e-6), truth


def test_the_series_default_to_the_first_revolute_joints():
    assert LIFT.ntm_joints == (2, 3, 4)
    meas, _ = _points(10, 0)
    assert spec_for(LIFT, meas, "full").ntm_joints == (2, 3, 4)
    assert {s.ntm_joints for _, s in candidate_specs(LIFT, meas)} == {(), (2, 3, 4)}


def test_a_sliding_first_joint_calibrates():
    """The truth has transmission errors and compliance: the full model predicts
    held-out poses to a tenth of the nominal error, the kinematic one less well."""
    train, _ = _points(150, 1)
    test, _ = _points(300, 2)
    held = {}
    for model in ("kinematic", "full"):
        res = calibrate(LIFT, train, model)
        assert res.success, model
        held[model] = evaluate(res.calibrated, test).metrics.rms_mm
        cal = res.calibrated
        nominal = replace(cal, params=res.registered)
        held["nominal"] = evaluate(nominal, test).metrics.rms_mm
    assert held["full"] < 0.1 * held["nominal"], held
    assert held["full"] < 0.5 * held["kinematic"] < 0.5 * held["nominal"], held


def test_auto_on_a_sliding_first_joint():
    train, _ = _points(120, 3)
    sel = select_model(
        LIFT, train, k=4, options=CalibrationOptions(), prior_scales=(1.0,)
    )
    assert sel.candidates and sum(c.chosen for c in sel.candidates) == 1


def test_a_series_on_the_slide_is_refused_by_name(tmp_path, run_cli):
    import yaml

    from kinecal.io import write_measurements
    from kinecal.robot import dump_robot

    meas, _ = _points(40, 4)
    robot_file = tmp_path / "lift.yaml"
    robot_file.write_text(yaml.safe_dump(dump_robot(LIFT)))
    data = tmp_path / "d.csv"
    write_measurements(data, meas, LIFT)
    r = run_cli(
        "calibrate",
        str(data),
        "--robot",
        str(robot_file),
        "--model",
        "ntm",
        "--ntm-joints",
        "1,2",
        "--out",
        str(tmp_path / "o"),
        "--no-report",
        "-q",
    )
    assert r.returncode == 2
    assert "--ntm-joints" in r.stderr and "joint 1 is not a revolute joint" in r.stderr
    assert "Traceback" not in r.stderr
