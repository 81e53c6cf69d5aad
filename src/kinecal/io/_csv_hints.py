"""Hints for data files whose columns kinecal does not read but can recognise."""

from __future__ import annotations

from collections.abc import Sequence

from kinecal.robot import RobotDescription

__all__ = ["named_joints_hint"]


def named_joints_hint(header: Sequence[str], robot: RobotDescription) -> str:
    """For a file without ``jK_...`` columns: a hint when its columns are named after
    the robot's joints (a ROS ``joint_states`` export, in radians and metres), else ''."""
    names = {c.lower(): c for c in header}
    named = [
        names.get(j.lower()) or names.get(f"{j}_joint".lower())
        for j in robot.joint_names
    ]
    if not any(named):
        return ""
    pairs = ", ".join(
        f"{c} -> j{k + 1}_{'m' if j.kind == 'prismatic' else 'rad'}"
        for k, (c, j) in enumerate(zip(named, robot.joints))
        if c
    )
    return (
        "; columns named after its joints (as ROS joint_states) are not read: rename "
        f"them in the robot's joint order, with their unit ({pairs}: radians and "
        "metres, as ROS gives them)"
    )
