"""A robot file whose numbers are all in another unit than its ``units`` say.

Each number of such a file passes its own check (a limit of 2.97 is a fine angle in
degrees, a link of 0.33 a fine length in mm), and the robot loads: ``simulate`` and
``plan`` then move every joint within +-3 deg, and ``fk`` puts the flange a millimetre
from the base. Taken together they cannot be a robot's, and the file is refused.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kinecal.errors import ConfigError
from kinecal.robot._description import JointSpec

__all__ = ["arm_length_m", "check_unit_slips"]

# Every revolute joint limited within one radian's worth of degrees around zero (6.3 deg
# at most): no arm is; its limits are radians. A whole arm of under 10 mm: metres.
_RAD_AS_DEG = np.radians(2 * np.pi + 1e-6)
_ARM_MIN_M = 0.010


def arm_length_m(joints: Sequence[JointSpec], ends: Sequence[np.ndarray]) -> float:
    """The arm's lengths added up [m]: its DH ``a`` and ``d`` and the offsets of its
    ``ends`` (flange and tool frames, 4 x 4): about its reach."""
    rows = sum(abs(j.a) + abs(j.d) for j in joints)
    return rows + sum(float(np.linalg.norm(T[:3, 3])) for T in ends)


def check_unit_slips(
    joints: Sequence[JointSpec],
    ends: Sequence[np.ndarray],
    source: str,
    length: str,
    angle: str,
) -> None:
    """ConfigError when every limit of a degrees file is within +-2 pi (radians) or the
    DH lengths of an mm file and its ``ends`` (flange and tool frames, 4 x 4) add up to
    under 10 mm (metres)."""
    revolute = [j for j in joints if j.kind != "prismatic"]
    lim = np.array([j.limits for j in revolute], float).reshape(-1, 2)
    finite = np.isfinite(lim).all(axis=1)
    if (
        angle == "deg"
        and finite.sum() >= 2
        and np.all(np.abs(lim[finite]) <= _RAD_AS_DEG)
    ):
        hi = float(np.degrees(np.abs(lim[finite]).max()))
        raise ConfigError(
            f"{source}: joints[*].limits: every revolute joint's limits lie within "
            f"+-{hi:.3g} deg; expected degrees (units.angle: deg): are they radians? "
            "Convert them, or set units.angle: rad."
        )
    reach = arm_length_m(joints, ends)
    if length == "mm" and 0.0 < reach < _ARM_MIN_M:
        raise ConfigError(
            f"{source}: joints[*].a, d: the arm's lengths (DH, flange, tool) add up to "
            f"{reach * 1e3:.3g} mm; expected millimetres (units.length: mm): are they "
            "metres? Convert them, or set units.length: m."
        )
