"""A URDF whose arm hangs from a ceiling or a wall (``world -> base_link`` turned by a
fixed joint): gravity stays the root link's -z, so in the base link's frame it points
along +z (ceiling) or +x (wall turned 90 deg about y). Before, import-urdf and
``--robot ROBOT.urdf`` put it along the base link's -z whatever the mount, and the
gravity compliance of a hanging arm was modelled as if it stood on the floor."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.robot import load_robot, robot_from_urdf

G = 9.80665
_JOINTS = [  # xyz, axis
    ((0, 0, 0.4), (0, 0, 1)),
    ((0.15, 0, 0.1), (0, 1, 0)),
    ((0, 0, 0.6), (0, 1, 0)),
    ((0.3, 0, 0.1), (1, 0, 0)),
    ((0.35, 0, 0), (0, 1, 0)),
    ((0.08, 0, 0), (1, 0, 0)),
]


def _urdf(mount_rpy: tuple[float, float, float]) -> str:
    r, p, y = mount_rpy
    out = [
        '<robot name="hung">',
        '<link name="world"/><link name="base_link"/>',
        '<joint name="mount" type="fixed"><parent link="world"/>'
        f'<child link="base_link"/><origin xyz="0.5 0.2 2.5" rpy="{r} {p} {y}"/></joint>',
    ]
    parent = "base_link"
    for i, (xyz, axis) in enumerate(_JOINTS, 1):
        out.append(
            f'<link name="l{i}"><inertial><mass value="{8 - i}"/>'
            '<origin xyz="0.05 0 0.05"/><inertia ixx="0.01" iyy="0.01" izz="0.01" '
            'ixy="0" ixz="0" iyz="0"/></inertial></link>'
        )
        out.append(
            f'<joint name="j{i}" type="revolute"><parent link="{parent}"/>'
            f'<child link="l{i}"/><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}"/>'
            f'<axis xyz="{axis[0]} {axis[1]} {axis[2]}"/>'
            '<limit lower="-2" upper="2" effort="1" velocity="1"/></joint>'
        )
        parent = f"l{i}"
    out.append("</robot>")
    return "\n".join(out)


@pytest.mark.parametrize(
    ("rpy", "gravity"),
    [
        ((0.0, 0.0, 0.7), (0, 0, -G)),  # on the floor, turned about z: unchanged
        ((np.pi, 0.0, 0.0), (0, 0, G)),  # ceiling
        ((0.0, np.pi / 2, 0.0), (G, 0, 0)),  # wall
    ],
)
def test_gravity_follows_the_mount(tmp_path, run_cli_here, rpy, gravity):
    urdf = tmp_path / "hung.urdf"
    urdf.write_text(_urdf(rpy))
    assert robot_from_urdf(urdf).gravity == pytest.approx(gravity, abs=1e-9)
    out = tmp_path / "robot.yaml"
    res = run_cli_here("import-urdf", str(urdf), "--out", str(out))
    assert res.returncode == 0, res.stderr
    robot = load_robot(str(out))
    assert robot.gravity / np.linalg.norm(robot.gravity) == pytest.approx(
        np.array(gravity) / G, abs=1e-9
    )
    # the base stays base_link: a pose of the arm is unchanged by the mount
    assert robot.fk_flange(np.zeros(6))[:3, 3] == pytest.approx([0.88, 0.0, 1.2])


@pytest.mark.filterwarnings("ignore:.*movable joints")
def test_vendor_dual_arm_hangs_from_its_frame():
    """denso_dual.urdf: two arms hung from a frame 1.9 m up (rpy 3.14 0 -1.57): each
    arm's gravity points up its base link's z axis (it was -z, an arm on the floor)."""
    from pathlib import Path

    urdf = Path(__file__).resolve().parents[1] / "data/vendor_urdf/denso_dual.urdf"
    for tip in ("J6_1", "J6_2"):
        g = robot_from_urdf(urdf, tip=tip).gravity
        assert g[2] > 0.999 * G, (tip, g)
