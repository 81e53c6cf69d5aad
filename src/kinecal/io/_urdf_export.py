"""Writers for the calibrated kinematic part: URDF and the robot YAML (a DH table).

URDF joint origins are ``xyz`` and fixed-axis ``rpy`` (``R = Rz(yaw) Ry(pitch) Rx(roll)``).
Roll-pitch-yaw lose precision next to ``pitch = +-90 deg`` (roll and yaw become one
angle; a DH row with ``alpha = -90`` followed by ``theta_offset = -90``, the LR Mate's J2,
sits exactly there), so such an origin is written as two: a fixed joint ``<name>_pre``
turning 90 deg about x into a link ``<name>_pre``, then the joint itself. Which joints are
split is decided on the nominal robot (``stable_splits``): every calibration of one robot
has the same links. Numbers are written with 17 significant digits, so the file reproduces the chain
to rounding (1e-15 m).
"""

from __future__ import annotations

from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from kinecal import _yaml as yaml
from kinecal.compensation import Element, ExportedChain
from kinecal.geometry import matrix_to_rpy, rot_x, transform_to_euler
from kinecal.robot import RobotDescription, dump_robot
from kinecal.typing import Pose

__all__ = [
    "joint_rates",
    "robot_named_chain",
    "robot_yaml_text",
    "stable_splits",
    "urdf_text",
]

_NEAR_LOCK = 0.995  # |sin(pitch)| above which an origin is split in two
_SPLIT_NOMINAL = 0.9  # the same, on the nominal robot (stable_splits)
_Q_PRE = np.eye(4)
_Q_PRE[:3, :3] = rot_x(np.pi / 2)


def _num(v: float) -> str:
    return repr(float(v) + 0.0)  # 17 significant digits at most, -0.0 as 0.0


def _origin(T: Pose) -> str:
    xyz = " ".join(_num(v) for v in T[:3, 3])
    rpy = " ".join(_num(v) for v in matrix_to_rpy(T[:3, :3]))
    return f'<origin xyz="{xyz}" rpy="{rpy}"/>'


def _comment(lines: list[str]) -> str:
    # "--" may not appear inside an XML comment.
    body = "\n".join(f"  {ln}".rstrip().replace("--", "- -") for ln in lines)
    return f"<!--\n{body}\n-->"


_PLACEHOLDER = (1.0, 1000.0)  # velocity [rad/s, m/s], effort [N m, N]: not the robot's


def _joint_xml(
    e: Element,
    parent: str,
    origin: Pose,
    rates: tuple[float | None, float | None] = (None, None),
) -> list[str]:
    kind = e.kind
    lim = e.limits
    finite = lim is not None and bool(np.all(np.isfinite(lim)))
    if kind == "revolute" and not finite:
        kind = "continuous"
    out = [f"  <joint name={quoteattr(e.name)} type={quoteattr(kind)}>"]
    out.append(f"    <parent link={quoteattr(parent)}/>")
    out.append(f"    <child link={quoteattr(e.child)}/>")
    out.append(f"    {_origin(origin)}")
    if e.kind != "fixed":
        out.append(f'    <axis xyz="{" ".join(_num(v) for v in e.axis)}"/>')
        if kind != "continuous":
            lo, hi = lim if finite and lim is not None else (-1e3, 1e3)  # m: no limit
            vel = rates[0] if rates[0] is not None else _PLACEHOLDER[0]
            eff = rates[1] if rates[1] is not None else _PLACEHOLDER[1]
            out.append(
                f'    <limit lower="{_num(lo)}" upper="{_num(hi)}" effort="{_num(eff)}" '
                f'velocity="{_num(vel)}"/>'
            )
        if e.mimic is not None:
            j, mult, off = e.mimic
            out.append(
                f"    <mimic joint={quoteattr(j)} multiplier={quoteattr(_num(mult))} "
                f"offset={quoteattr(_num(off))}/>"
            )
    out.append("  </joint>")
    return out


def stable_splits(cal, *, set_label: str | None = None, coupling: str = "kinematic"):
    """Names of the robot's joints whose origin :func:`urdf_text` writes as two (a
    ``<name>_pre`` link), decided on the nominal robot, so that every calibration of one
    robot has the same links (a calibrated origin is within a few degrees of the nominal
    one; the measurement and tool frames are never split)."""
    import numpy as np

    from kinecal.compensation import export_chain

    model = cal.model
    nominal = type(cal)(
        model, model.nominal.copy(), np.full(model.size, np.nan), ["fixed"] * model.size
    )
    chain = export_chain(nominal, set_label=set_label, coupling=coupling)
    frames = ("base_joint", "user_", "tool")
    return frozenset(
        e.name
        for e in chain.elements
        if not e.name.startswith(frames) and abs(e.origin[2, 0]) > _SPLIT_NOMINAL
    )


def urdf_text(
    chain: ExportedChain,
    *,
    name: str,
    comments: list[str],
    split: frozenset[str] | None = None,
    rates: dict[str, tuple[float | None, float | None]] | None = None,
) -> str:
    """The URDF document of an exported chain.

    Parameters
    ----------
    chain : ExportedChain (see :func:`kinecal.compensation.export_chain`).
    name : robot name.
    comments : lines of the comment block at the top (units, what is left out).
    split : the elements written as two (:func:`stable_splits`); default: those whose
        origin is within ~6 deg of the roll-pitch-yaw lock (depends on the values).
    rates : joint name -> (velocity, effort) of its ``<limit>``; where unknown (None or
        not listed) the placeholders 1 rad/s (m/s) and 1000 N m (N), never 0 (which
        MoveIt and Gazebo read as a frozen joint).
    """
    links = [chain.root]
    joints: list[str] = []
    for e in chain.elements:
        parent, origin = e.parent, e.origin
        near = abs(origin[2, 0]) > _NEAR_LOCK
        if near if split is None else e.name in split:
            pre = f"{e.name}_pre"
            joints += _joint_xml(
                Element(pre, "fixed", parent, pre, _Q_PRE), parent, _Q_PRE
            )
            links.append(pre)
            parent, origin = pre, np.linalg.inv(_Q_PRE) @ origin
        joints += _joint_xml(e, parent, origin, (rates or {}).get(e.name, (None, None)))
        links.append(e.child)
    out = ['<?xml version="1.0"?>', _comment(comments)]
    out.append(f"<robot name={quoteattr(name)}>")
    out += [f"  <link name={quoteattr(lk)}/>" for lk in links]
    out += joints
    out.append("</robot>")
    return "\n".join(out) + "\n"


def _frame_dict_full(T: Pose) -> dict[str, float]:
    """``{x, y, z, r, w, p}`` [mm, deg] of a frame, unrounded."""
    v = transform_to_euler(T)
    return {
        **{k: float(x * 1e3) for k, x in zip("xyz", v[:3])},
        **{k: float(np.degrees(x)) for k, x in zip("rwp", v[3:])},
    }


def robot_yaml_text(robot: RobotDescription, *, comments: list[str]) -> str:
    """The robot YAML of a description with unrounded numbers (``dump_robot`` rounds to
    1e-9 mm and deg, which a DH table with a far common normal cannot afford)."""
    doc: dict[str, Any] = dump_robot(robot)
    for row, j in zip(doc["joints"], robot.joints):
        row["theta_offset"] = float(np.degrees(j.theta_offset))
        row["d"] = float(j.d * 1e3)
        row["a"] = float(j.a * 1e3)
        row["alpha"] = float(np.degrees(j.alpha))
        if "limits" in row:
            row["limits"] = [round(float(v), 9) for v in row["limits"]]
    if "frame0" in doc:
        doc["frame0"] = _frame_dict_full(robot.T_base_0)
    doc["flange"] = _frame_dict_full(robot.T_n_flange)
    doc["tool"] = _frame_dict_full(robot.T_flange_tool)
    head = "".join(f"# {ln}".rstrip() + "\n" for ln in comments)
    return head + yaml.dump(_no_negative_zero(doc), sort_keys=False, width=100)


def _no_negative_zero(v: Any) -> Any:
    """``v`` with every -0.0 made 0.0 (a rounded -1e-12 mm is not a negative length)."""
    if isinstance(v, dict):
        return {k: _no_negative_zero(x) for k, x in v.items()}
    if isinstance(v, list):
        return [_no_negative_zero(x) for x in v]
    return v + 0.0 if isinstance(v, float) else v


def joint_rates(robot: RobotDescription, chain: ExportedChain):
    """(velocity, effort) per movable element of an exported chain, from the robot's
    joints: a joint in kinematic angles ``theta_i = sum_k C_ik q_k`` moves at most at
    ``sum_k |C_ik| v_k``; a mimic element at ``|multiplier|`` times its joint's."""
    import numpy as np

    v = [j.velocity for j in robot.joints]
    f = [j.effort for j in robot.joints]
    C = robot.coupling
    out: dict[str, tuple[float | None, float | None]] = {}
    for i, name in enumerate(chain.joints):
        if chain.coupling == "kinematic":
            ks = np.flatnonzero(C[i])
            known = all(v[k] is not None for k in ks)
            vel = float(sum(abs(C[i, k]) * v[k] for k in ks)) if known else None
        else:
            vel = v[i]
        out[name] = (vel, f[i])
    for e in chain.elements:
        if e.mimic is not None:
            k = chain.joints.index(e.mimic[0])
            vk = v[k]
            out[e.name] = (abs(e.mimic[1]) * vk if vk is not None else None, f[k])
    return out


def _clean(name: str) -> str:
    return "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in name)


def robot_named_chain(robot: RobotDescription, chain: ExportedChain):
    """The chain with ROS-style names (``export-urdf --names robot``): the robot's own
    joint names (an imported URDF's, a robot file's), links ``base_link``,
    ``link_1..link_N``, ``flange``, ``tool0`` (``tool0_<marker>``), rooted at
    ``base_link`` (the calibrated robot base) with the measurement frame ``user`` as a
    fixed child. Returns the chain and the renaming (old -> new) of its joints."""
    from dataclasses import replace

    import numpy as np

    own = [_clean(j.name) for j in robot.joints]
    if len(set(own)) < len(own) or any(not n for n in own):
        own = [f"joint_{i + 1}" for i in range(len(own))]
    jmap = {f"j{i + 1}": own[i] for i in range(len(own))}
    lmap = {"base": "base_link", "flange": "flange"}
    lmap.update({f"link{i + 1}": f"link_{i + 1}" for i in range(len(own))})
    for tip in chain.tips.values():
        lmap[tip] = "tool0" if tip == "tool" else "tool0_" + tip.removeprefix("tool_")
    for e in chain.elements:
        if e.mimic is not None:  # j3_from_j2 -> J3_from_J2
            a, b = e.name.removeprefix("j").split("_from_j")
            jmap[e.name] = f"{own[int(a) - 1]}_from_{own[int(b) - 1]}"
            lmap[e.child] = jmap[e.name] + "_link"
    renamed: dict[str, str] = {}
    els = []
    for e in chain.elements:
        if e.name == "base_joint":  # user -> base, turned round: base_link -> user
            els.append(
                replace(
                    e,
                    name="user_joint",
                    parent="base_link",
                    child=chain.root,
                    origin=np.asarray(np.linalg.inv(e.origin), dtype=np.float64),
                )
            )
            continue
        name = jmap.get(e.name, e.name)
        if e.name.endswith("_joint") and e.child in lmap:  # flange_joint, tool_joint
            name = lmap[e.child] + "_joint"
        renamed[e.name] = name
        mimic = e.mimic
        if mimic is not None:
            mimic = (jmap.get(mimic[0], mimic[0]), mimic[1], mimic[2])
        els.append(
            replace(
                e,
                name=name,
                parent=lmap.get(e.parent, e.parent),
                child=lmap.get(e.child, e.child),
                mimic=mimic,
            )
        )
    # parents before children: base_link's user frame first
    els.sort(key=lambda e: e.name != "user_joint")
    out = replace(
        chain,
        elements=tuple(els),
        root="base_link",
        joints=tuple(jmap[j] for j in chain.joints),
        tips={label: lmap[tip] for label, tip in chain.tips.items()},
    )
    return out, renamed
