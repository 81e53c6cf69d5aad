"""Built-in FANUC descriptions against the reference vectors and two independent evaluations."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kinecal.geometry import matrix_to_wpr, wpr_to_matrix
from kinecal.robot import load_robot
from tests.tolerances import INDEPENDENT_MM, VECTOR_ROUNDING_MM
from tests.urdf_reference import urdf_chain_fk

DATA = Path(__file__).parents[1] / "data" / "fanuc_lrmate200id"
VECTORS = json.loads((DATA / "test_vectors.json").read_text())
WORLD_Z_MM = 330.0  # FANUC World = URDF base_link + 330 mm (J2 height)


def _robot_for(key: str) -> str:
    return (
        "fanuc-lrmate200id-7l"
        if key.startswith("lrmate200id7l")
        else "fanuc-lrmate200id"
    )


@pytest.mark.parametrize("key", sorted(VECTORS))
def test_reference_vectors(key):
    v = VECTORS[key]
    robot = load_robot(_robot_for(key))
    T = robot.fk_flange(np.radians(v["J_ctrl_deg"]))
    np.testing.assert_allclose(
        T[:3, 3] * 1e3, v["flange_world_mm"], atol=VECTOR_ROUNDING_MM
    )
    # Compare rotations as matrices: WPR is not unique at P = +-90 deg.
    R_ref = wpr_to_matrix(np.radians(v["wpr_deg"]))
    # WPR is printed to 1e-4 deg: up to 3 x 0.5e-4 deg = 2.6e-6 rad of rounding.
    np.testing.assert_allclose(T[:3, :3], R_ref, atol=3e-6)
    # theta3 = J3 + J2 (coupling) is what the URDF calls J3.
    np.testing.assert_allclose(
        np.degrees(robot.theta_from_ctrl(np.radians(v["J_ctrl_deg"]))),
        v["q_urdf_deg"],
        atol=1e-9,
    )


@pytest.mark.parametrize(
    ("robot_name", "urdf", "tip"),
    [
        ("fanuc-lrmate200id", "rosi_lrmate200id.urdf", "tool0"),
        ("fanuc-lrmate200id", "fanuc_lrmate200id.urdf", "fanuc_flange"),
        ("fanuc-lrmate200id-7l", "rosi_lrmate200id7l.urdf", "tool0"),
        ("fanuc-lrmate200id-7l", "fanuc_lrmate200id7l.urdf", "fanuc_flange"),
    ],
)
def test_matches_independent_urdf_chain(robot_name, urdf, tip, rng):
    robot = load_robot(robot_name)
    lim = robot.limits
    q_ctrl = rng.uniform(lim[:, 0], lim[:, 1], size=(300, 6))
    q_urdf = robot.theta_from_ctrl(q_ctrl)
    T = robot.fk_flange(q_ctrl)
    for k in range(0, 300, 7):
        T_ref = urdf_chain_fk(DATA / urdf, "base_link", tip, q_urdf[k])
        T_ref[2, 3] -= WORLD_Z_MM * 1e-3
        np.testing.assert_allclose(
            T[k, :3, 3] * 1e3, T_ref[:3, 3] * 1e3, atol=INDEPENDENT_MM
        )
        np.testing.assert_allclose(T[k, :3, :3], T_ref[:3, :3], atol=1e-12)


def test_matches_pinocchio(rng):
    pin = pytest.importorskip(
        "pinocchio", reason="pinocchio (pip install pin) not installed"
    )
    for robot_name, urdf in (
        ("fanuc-lrmate200id", "rosi_lrmate200id.urdf"),
        ("fanuc-lrmate200id-7l", "rosi_lrmate200id7l.urdf"),
    ):
        model = pin.buildModelFromXML((DATA / urdf).read_text())
        data = model.createData()
        fid = model.getFrameId("tool0")
        robot = load_robot(robot_name)
        lim = robot.limits
        q_ctrl = rng.uniform(lim[:, 0], lim[:, 1], size=(200, 6))
        T = robot.fk_flange(q_ctrl)
        for k in range(200):
            pin.framesForwardKinematics(model, data, robot.theta_from_ctrl(q_ctrl[k]))
            M = data.oMf[fid]
            np.testing.assert_allclose(
                T[k, :3, 3] * 1e3,
                M.translation * 1e3 - [0, 0, WORLD_Z_MM],
                atol=INDEPENDENT_MM,
            )
            np.testing.assert_allclose(T[k, :3, :3], M.rotation, atol=1e-12)


def test_fk_is_vectorised_over_batch_shapes(rng):
    robot = load_robot("fanuc-lrmate200id")
    q = rng.uniform(-1, 1, size=(4, 5, 6))
    T = robot.fk_flange(q)
    assert T.shape == (4, 5, 4, 4)
    np.testing.assert_allclose(T[2, 3], robot.fk_flange(q[2, 3]), atol=1e-15)


def test_wpr_output_of_zero_pose():
    T = load_robot("fanuc-lrmate200id").fk_flange(np.zeros(6))
    np.testing.assert_allclose(T[:3, 3] * 1e3, [465.0, 0.0, 365.0], atol=1e-9)
    np.testing.assert_allclose(
        np.degrees(matrix_to_wpr(T[:3, :3]))[1], -90.0, atol=1e-9
    )


def test_builtin_json_is_the_yaml_files_parsed():
    """The commands read the built-in robots from data/builtin.json; after a change to a
    YAML file, `python -m kinecal.robot._builtin` writes it again."""
    import json

    from kinecal.robot import _builtin

    stored = json.loads(_builtin._JSON.read_text(encoding="utf-8"))["robots"]
    assert stored == _builtin.parsed_yaml_documents(), (
        "robot/data/builtin.json is out of date: run python -m kinecal.robot._builtin"
    )


def test_a_builtin_robot_loads_without_pyyaml():
    import subprocess
    import sys

    code = (
        "import sys\nfrom kinecal.robot import load_robot\n"
        "r = load_robot('fanuc-lrmate200id')\nassert r.n_joints == 6\n"
        "print('yaml' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
