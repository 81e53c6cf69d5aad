"""A joint's speed and effort limits (a robot file's ``velocity`` and ``effort``, a URDF's
``<limit velocity effort>``): bounded to what a robot joint can have, in SI.

A joint of an industrial or collaborative arm turns at a few thousand deg/s at most (the
fastest, SCARA wrists, near 3000 deg/s); linear axes move at a few m/s; the largest arms'
joint torques are some 10^5 N m. A value beyond these bounds (``1e30``, as some files
write for "unlimited") is no joint's: a robot file refuses it, naming the field; a URDF's
is read as unknown, as a missing or non-positive one is.
"""

from __future__ import annotations

import numpy as np

from kinecal.errors import ConfigError

__all__ = ["MAX_EFFORT", "MAX_SPEED", "check_rate", "rate_or_none"]

# Upper bounds [SI] by (key, prismatic): 20 turns a second (7200 deg/s), 20 m/s, and
# 10^6 N m (N for a linear axis).
MAX_SPEED = {False: 40.0 * np.pi, True: 20.0}
MAX_EFFORT = 1e6


def _bound(key: str, prismatic: bool) -> float:
    return MAX_SPEED[prismatic] if key == "velocity" else MAX_EFFORT


def rate_or_none(value: float, key: str, prismatic: bool) -> float | None:
    """``value`` [SI] of a URDF ``<limit>`` attribute, or None where it is no joint's
    (not a number, not positive, beyond :data:`MAX_SPEED` / :data:`MAX_EFFORT`)."""
    ok = np.isfinite(value) and 0.0 < value <= _bound(key, prismatic)
    return float(value) if ok else None


def check_rate(
    value: float, key: str, prismatic: bool, scale: float, where: str
) -> float:
    """A robot file's ``velocity`` or ``effort`` (``value`` in the file's units,
    ``scale`` to SI) in SI; ConfigError naming ``where`` and the expected range when it
    is not a positive value within the bound.

    Parameters
    ----------
    value : the file's number (deg/s or rad/s, mm/s or m/s; N m or N).
    key : ``'velocity'`` or ``'effort'``.
    prismatic : the joint is linear.
    scale : the file's unit per SI unit of ``value`` (velocity: the length or angle
        unit; effort: 1).
    where : ``FILE: joints[i]`` (the field is appended).
    """
    bound = _bound(key, prismatic)
    if key == "velocity":
        unit = ("mm/s" if scale == 1e-3 else "m/s") if prismatic else None
        unit = unit or ("deg/s" if scale != 1.0 else "rad/s")
        what = "a joint speed"
        note = "" if prismatic else " (20 turns a second)"
    else:
        unit, what = ("N" if prismatic else "N m"), "a joint effort"
        note = " (a force)" if prismatic else " (a torque)"
    if not (np.isfinite(value) and value > 0.0 and value * scale <= bound):
        raise ConfigError(
            f"{where}.{key}: {value:g} {unit}; expected {what} greater than 0 and at "
            f"most {bound / scale:.6g} {unit}{note}."
        )
    return float(value * scale)
