"""``export-urdf --format ur-calibration``: the ``kinematics.yaml`` of the Universal Robots
ROS driver (what ``ur_calibration`` extracts from a controller; format facts from the
driver's documentation and published calibration files: ``kinematics:`` with
``shoulder``, ``upper_arm``, ``forearm``, ``wrist_1``, ``wrist_2``, ``wrist_3``, each
``x y z roll pitch yaw`` [m, rad], the origins of ``ur_description``'s six joints, and
``hash: calib_<digits>``).
"""

from __future__ import annotations

import hashlib

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import matrix_to_rpy
from kinecal.io._urdf_like import like_urdf
from kinecal.io._urdf_like_steps import num as _num

__all__ = ["ur_calibration_text"]

_UR_ALPHA = np.radians([90.0, 0.0, 0.0, 90.0, -90.0, 0.0])
_UR_PARTS = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")


def ur_calibration_text(cal, *, set_label: str | None = None, comments=()) -> str:
    """The ``kinematics.yaml`` of the Universal Robots ROS driver (``ur_calibration``'s
    output): the origins of ``ur_description``'s six joints, ``x y z roll pitch yaw``
    [m, rad], and a ``hash``, for the calibrated kinematic part of ``cal``.

    Raises
    ------
    ConfigError
        The model's robot is not a Universal Robots arm (its DH table).
    """
    robot = cal.model.robot
    ch = robot.dh_chain()
    ok = (
        robot.n_joints == 6
        and not np.any(robot.prismatic)
        and np.allclose(ch.alpha, _UR_ALPHA, atol=1e-6)
        and np.allclose(ch.theta_offset, 0.0, atol=1e-9)
        and np.allclose(ch.a[[0, 3, 4, 5]], 0.0, atol=1e-9)
        and np.allclose(ch.d[[1, 2]], 0.0, atol=1e-9)
        and np.allclose(robot.coupling, np.eye(6))
    )
    if not ok:
        raise ConfigError(
            f"--format ur-calibration: {robot.name} is not a Universal Robots arm "
            "(expected the UR DH table: 6 revolute joints, alpha 90 0 0 90 -90 0 deg, "
            "no offsets, a1 = a4 = a5 = a6 = 0, d2 = d3 = 0)."
        )
    d, a = ch.d, ch.a
    org = [
        (0, 0, d[0], 0, 0, 0),
        (0, 0, 0, np.pi / 2, 0, 0),
        (a[1], 0, 0, 0, 0, 0),
        (a[2], 0, d[3], 0, 0, 0),
        (0, -d[4], 0, np.pi / 2, 0, 0),
        (0, d[5], 0, np.pi / 2, np.pi, np.pi),
    ]
    lines = ['<robot name="ur">', '  <link name="base_link_inertia"/>']
    parent = "base_link_inertia"
    lims = np.where(np.isfinite(robot.limits), robot.limits, [-2 * np.pi, 2 * np.pi])
    for part, row, (lo, hi) in zip(_UR_PARTS, org, lims):
        o = [float(v) for v in row]
        lines += [
            f'  <link name="{part}_link"/>',
            f'  <joint name="{part}_joint" type="revolute">',
            f'    <parent link="{parent}"/><child link="{part}_link"/>',
            f'    <origin xyz="{o[0]!r} {o[1]!r} {o[2]!r}" rpy="{o[3]!r} {o[4]!r} {o[5]!r}"/>',
            '    <axis xyz="0 0 1"/>',
            f'    <limit lower="{float(lo)!r}" upper="{float(hi)!r}"/>',
            "  </joint>",
        ]
        parent = f"{part}_link"
    lines.append("</robot>")
    res = like_urdf(
        cal,
        f"<the ur_description chain of {robot.name}>",
        set_label=set_label,
        tool_link="kinecal_tool",
        text="\n".join(lines) + "\n",
    )
    out = [f"# {ln}".rstrip() for ln in comments]
    out.append("kinematics:")
    values = []
    for part in _UR_PARTS:
        O = res.origins[f"{part}_joint"]
        v = [*O[:3, 3], *matrix_to_rpy(O[:3, :3])]
        values += v
        out.append(f"  {part}:")
        out += [
            f"    {k}: {_num(x)}"
            for k, x in zip(("x", "y", "z", "roll", "pitch", "yaw"), v)
        ]
    digest = hashlib.blake2b(repr(values).encode(), digest_size=8).digest()
    out.append(f"  hash: calib_{int.from_bytes(digest, 'big')}")
    return "\n".join(out) + "\n"
