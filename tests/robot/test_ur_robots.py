"""Built-in Universal Robots (issue 20, point 4): the vendor's DH tables against the URDF
joint origins of ROS-Industrial's ur_description, evaluated independently."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kinecal.robot import builtin_robot_names, load_robot
from tests.tolerances import INDEPENDENT_MM
from tests.urdf_reference import urdf_chain_fk

DATA = Path(__file__).parents[1] / "data" / "ur_e_series"
ORIGINS = json.loads((DATA / "default_kinematics.json").read_text())
JOINTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
LINKS = (
    "base_link_inertia",
    "shoulder_link",
    "upper_arm_link",
    "forearm_link",
    "wrist_1_link",
    "wrist_2_link",
    "wrist_3_link",
)
# Universal Robots' DH tables (mm): d1, a2, a3, d4, d5, d6 (PROVENANCE.md).
VENDOR_MM = {
    "ur3e": (151.85, -243.55, -213.2, 131.05, 85.35, 92.1),
    "ur5e": (162.5, -425.0, -392.2, 133.3, 99.7, 99.6),
    "ur10e": (180.7, -612.7, -571.55, 174.15, 119.85, 116.55),
    "ur10": (127.3, -612.0, -572.3, 163.941, 115.7, 92.2),
}
RATED_KG = {"ur3e": 3.0, "ur5e": 5.0, "ur10e": 12.5, "ur10": 10.0}


def _urdf(name: str) -> str:
    """The kinematic chain of ur_description's macro with the joint origins of ``name``:
    base_link_inertia (the controller's base) to tool0."""

    def origin(xyzrpy) -> str:
        x = " ".join(repr(float(v)) for v in xyzrpy[:3])
        r = " ".join(repr(float(v)) for v in xyzrpy[3:])
        return f'<origin xyz="{x}" rpy="{r}"/>'

    parts = [f'<robot name="{name}">']
    parts += [f'<link name="{n}"/>' for n in (*LINKS, "flange", "tool0")]
    for k, j in enumerate(JOINTS):
        parts.append(
            f'<joint name="{j}_joint" type="revolute"><parent link="{LINKS[k]}"/>'
            f'<child link="{LINKS[k + 1]}"/>{origin(ORIGINS[name][j])}'
            '<axis xyz="0 0 1"/><limit lower="-6.3" upper="6.3" effort="1" '
            'velocity="1"/></joint>'
        )
    h = np.pi / 2
    parts.append(
        '<joint name="wrist_3-flange" type="fixed"><parent link="wrist_3_link"/>'
        f'<child link="flange"/>{origin([0, 0, 0, 0, -h, -h])}</joint>'
    )
    parts.append(
        '<joint name="flange-tool0" type="fixed"><parent link="flange"/>'
        f'<child link="tool0"/>{origin([0, 0, 0, h, 0, h])}</joint>'
    )
    return "\n".join([*parts, "</robot>"])


@pytest.mark.parametrize("name", sorted(VENDOR_MM))
def test_issue_20_dh_table_limits_and_rated_payload(name):
    robot = load_robot(name)
    assert name in builtin_robot_names()
    d = [j.d * 1e3 for j in robot.joints]
    a = [j.a * 1e3 for j in robot.joints]
    np.testing.assert_allclose(
        [d[0], a[1], a[2], d[3], d[4], d[5]], VENDOR_MM[name], atol=1e-9
    )
    assert d[1] == d[2] == a[0] == a[3] == a[4] == a[5] == 0.0
    np.testing.assert_allclose(
        np.degrees([j.alpha for j in robot.joints]), [90, 0, 0, 90, -90, 0], atol=1e-12
    )
    np.testing.assert_allclose(np.degrees(robot.limits), [[-360, 360]] * 6)
    assert robot.rated_payload_kg == RATED_KG[name]


@pytest.mark.parametrize("name", sorted(VENDOR_MM))
def test_issue_20_fk_matches_the_urdf_chain(name, rng, tmp_path):
    robot = load_robot(name)
    path = tmp_path / f"{name}.urdf"
    path.write_text(_urdf(name))
    q = rng.uniform(-np.pi, np.pi, size=(60, 6))
    T = robot.fk_flange(q)
    for k in range(q.shape[0]):
        T_ref = urdf_chain_fk(path, "base_link_inertia", "tool0", q[k])
        np.testing.assert_allclose(
            T[k, :3, 3] * 1e3, T_ref[:3, 3] * 1e3, atol=INDEPENDENT_MM
        )
        # roll = 1.570796327 in the published files: 2e-10 rad from pi/2
        np.testing.assert_allclose(T[k, :3, :3], T_ref[:3, :3], atol=1e-9)


def test_issue_20_fk_matches_pinocchio(rng):
    pin = pytest.importorskip("pinocchio", reason="pinocchio not installed")
    for name in ("ur3e", "ur5e", "ur10e"):
        model = pin.buildModelFromXML(_urdf(name))
        data = model.createData()
        fid = model.getFrameId("tool0")
        robot = load_robot(name)
        q = rng.uniform(-2 * np.pi, 2 * np.pi, size=(40, 6))
        T = robot.fk_flange(q)
        for k in range(q.shape[0]):
            pin.framesForwardKinematics(model, data, q[k])
            M = data.oMf[fid]
            np.testing.assert_allclose(
                T[k, :3, 3] * 1e3, M.translation * 1e3, atol=INDEPENDENT_MM
            )
            np.testing.assert_allclose(T[k, :3, :3], M.rotation, atol=1e-9)


def test_issue_20_ur10_and_ur10e_tables_differ_where_the_mocap_data_say():
    """The CB table's d4, d5 are 10.2 and 4.15 mm shorter than the UR10e's: what a fit
    of the UR10 table on the FIGAROH poses finds (+12 +- 5, +4 +- 3 mm, examples/)."""
    cb, e = load_robot("ur10"), load_robot("ur10e")
    diff = [(j.d - i.d) * 1e3 for i, j in zip(cb.joints, e.joints)]
    np.testing.assert_allclose(diff[3:5], [10.209, 4.15], atol=1e-9)
