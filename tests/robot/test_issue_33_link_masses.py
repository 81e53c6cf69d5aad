"""Issue 33: the link self-weight layout from a URDF's inertials, checked against an
independent simulator (tests/independent_arm.py: its own kinematics and gravity)."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import ConfigError
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
from kinecal.robot import dump_robot, load_robot, robot_from_dict, robot_from_urdf
from tests.independent_arm import ARM7, TORSO, UR6, random_poses, true_arm, urdf_text

ARMS = {"arm7": ARM7, "ur6": UR6, "torso": TORSO}


@pytest.fixture(params=sorted(ARMS))
def arm(request, tmp_path):
    name = request.param
    path = tmp_path / f"{name}.urdf"
    path.write_text(urdf_text(ARMS[name], name))
    return ARMS[name], robot_from_urdf(path, tip="flange")


def test_masses_lumped_per_body(arm):
    """Every URDF mass lands on the body its joint moves; the hand (fixed to the flange)
    joins the last body."""
    rows, robot = arm
    masses = {b.frame: b.mass for b in robot.link_masses}
    expected = {i + 1: r[3] for i, r in enumerate(rows)}
    expected[len(rows)] += 0.7
    assert masses == pytest.approx(expected)
    assert robot.self_weight is None


def test_gravity_deflection_matches_independent_truth(arm):
    """The general link model at its nominal (from the imported masses) with the true
    joint compliances predicts the independent simulator's deflected flange to 1e-9 m
    (torques at the commanded pose in both)."""
    rows, robot = arm
    truth = true_arm(0, arm=rows, exact=True)
    cm = CalibrationModel(
        robot,
        ModelSpec(
            cam_rotation=False, load=True, link="general", link_bodies=robot.link_bodies
        ),
    )
    x = cm.nominal.copy()
    for j in range(robot.n_joints):  # lambda* = |F| c with the 1 kg unit weight
        x[cm.layout.index(f"joint{j + 1}.lambda")] = truth.compliance[j] * 9.80665
    q = random_poses(50, np.random.default_rng(3), rows)
    inputs = ModelInputs.make(q, load_scale=np.zeros(len(q)))  # no payload
    p = cm.evaluate(x, inputs).p_user
    p_true = truth.measure(q, None, iterations=1)
    p_rigid = truth.measure(q, None, iterations=0)
    assert np.abs(p_true - p_rigid).max() > 1e-4  # the deflection is there
    np.testing.assert_allclose(p, p_true, atol=1e-9)


def test_link_masses_round_trip_and_errors(arm):
    _, robot = arm
    doc = dump_robot(robot)
    again = robot_from_dict(doc)
    assert [b.frame for b in again.link_masses] == [b.frame for b in robot.link_masses]
    for a, b in zip(again.link_masses, robot.link_masses):
        assert a.mass == pytest.approx(b.mass)
        np.testing.assert_allclose(a.com, b.com, atol=1e-11)
    assert again.self_weight is None
    bad = dict(doc, link_masses=[{"frame": 99, "mass_kg": 1.0, "com": [0, 0, 0]}])
    with pytest.raises(
        ConfigError, match=r"link_masses\[0\]\.frame: expected a DH frame"
    ):
        robot_from_dict(bad, "r.yaml")
    bad = dict(doc, link_masses=[{"frame": 2, "mass_kg": -1.0, "com": [0, 0, 0]}])
    with pytest.raises(ConfigError, match=r"link_masses\[0\]\.mass_kg"):
        robot_from_dict(bad, "r.yaml")
    bad = dict(doc, link_masses=[{"frame": 2, "mass_kg": 1.0, "com": [0, 0]}])
    with pytest.raises(
        ConfigError, match=r"link_masses\[0\]\.com: expected \[x, y, z\]"
    ):
        robot_from_dict(bad, "r.yaml")


def test_presets_use_the_general_model_only_without_a_lumped_layout(arm):
    _, robot = arm
    from kinecal.identification import Measurements
    from kinecal.identification._problem import spec_for

    q = np.zeros((3, robot.n_joints))
    meas = Measurements("point", q, np.zeros((3, 3)))
    full = spec_for(robot, meas, "full")
    assert full.link == "general" and full.link_bodies == robot.link_bodies
    fanuc = load_robot("fanuc-lrmate200id")  # the paper's lumped layout, J2/J3 coupled
    assert (
        spec_for(
            fanuc, Measurements("point", np.zeros((3, 6)), np.zeros((3, 3))), "full"
        ).link
        == "paper"
    )
    assert fanuc.coupling[2, 1] == 1.0


def test_fanuc_urdf_inertials():
    robot = robot_from_urdf(
        "tests/data/fanuc_lrmate200id/fanuc_lrmate200id.urdf", tip="J6_link"
    )
    assert [b.frame for b in robot.link_masses] == [1, 2, 3, 4, 5, 6]
    assert sum(b.mass for b in robot.link_masses) == pytest.approx(
        5.62 + 9.05 + 2.15 + 2.42 + 0.446 + 0.0134, rel=1e-9
    )


@pytest.mark.parametrize("scale", [0.0, 1.0])
def test_gravity_check_only_with_gravity_deflection(tmp_path, scale):
    """A robot without a self-weight layout: the check warns when the independent
    arm's joints yield to its link weights, and not when they do not."""
    from dataclasses import replace

    from kinecal.identification import Measurements, calibrate
    from kinecal.identification._gravity_check import gravity_check

    path = tmp_path / "arm7.urdf"
    path.write_text(urdf_text())
    robot = replace(robot_from_urdf(path, tip="flange"), link_masses=())
    rng = np.random.default_rng(5)
    q = random_poses(80, rng)
    truth = true_arm(2, compliance_scale=scale)
    meas = Measurements("point", q, truth.measure(q, rng))
    found = gravity_check(calibrate(robot, meas, "full"), meas)
    if scale:
        assert found is not None and "no self-weight layout" in found.message
    else:
        assert found is None
