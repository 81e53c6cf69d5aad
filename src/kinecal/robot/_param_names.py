"""The robot's joint names as aliases of the canonical parameter names.

Canonical parameter names are ``joint<K>.<field>`` (DESIGN.md); a robot whose joints
have names (a URDF's ``shoulder_lift_joint``) lets the user write
``shoulder_lift_joint.theta_offset`` for ``joint2.theta_offset``. Files keep the
canonical name; readers and options accept both.
"""

from __future__ import annotations

from collections.abc import Sequence


def canonical_parameter_name(name: str, joint_names: Sequence[str]) -> str:
    """``name`` with a leading joint name replaced by ``joint<K>``; else unchanged.

    Only names of the form ``<joint name>.<field>`` whose joint name is one of the
    robot's (and not itself a canonical ``joint<K>``) are rewritten.
    """
    head, dot, field = name.partition(".")
    if not dot or not field:
        return name
    matches = [k for k, jn in enumerate(joint_names, start=1) if jn == head]
    if len(matches) != 1 or head == f"joint{matches[0]}":
        return name
    return f"joint{matches[0]}.{field}"


def display_parameter_name(name: str, joint_names: Sequence[str]) -> str:
    """``joint<K>.<field>`` shown as ``<joint name>.<field>`` when joint K has a name."""
    head, dot, field = name.partition(".")
    if not dot or not head.startswith("joint") or not head[5:].isdigit():
        return name
    k = int(head[5:])
    if not 1 <= k <= len(joint_names) or joint_names[k - 1] in ("", head):
        return name
    if sum(jn == joint_names[k - 1] for jn in joint_names) != 1:
        return name
    return f"{joint_names[k - 1]}.{field}"
