"""``export-urdf --like VENDOR.urdf``: the vendor's URDF with calibrated joint origins.

Every link, joint, name, mesh, collision, inertial, limit and comment of the vendor's file
is kept; only the ``<origin>`` of the movable joints between the root and the last movable
joint changes, so that the forward kinematics root -> link equal the calibrated kinematic
part of the model while each link frame keeps its place relative to the axis of the joint
that moves it (the meshes attached to it stay where they were on the link).

How: both the model (:func:`kinecal.compensation.export_chain`) and the vendor file put a
frame on each joint axis, turning with the joint. In the nominal model and the vendor's
file the two frames of one joint differ by a constant transform ``H_i`` (found at the
zero pose and checked on random poses: a vendor file of another robot is refused). The
calibrated link frame is the calibrated joint frame times ``H_i``; the new joint origins
are read off between consecutive calibrated link frames. The joint axes (in the child
frame) never change: ``H_i`` keeps the axis through the link origin.

The robot base of the model is placed in the vendor's root frame by the joint axis lines
of the zero pose (rotation from their directions, translation from their positions), so
a built-in robot whose base frame differs from the vendor's root (FANUC World at J2 height,
base_link on the floor) matches too.

Coupled robots: the URDF joints take the kinematic angles ``theta = C q_ctrl`` (as the
ROS-Industrial FANUC files do).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import matrix_to_rpy
from kinecal.io._urdf_like_steps import (
    axis_of,
    check_link_names,
    exact_link,
    fixed_xml,
    motion,
    new_origins,
    num,
    place_base,
    read_vendor,
    with_comment,
)
from kinecal.robot._schema import check_travel
from kinecal.robot._urdf import _limits
from kinecal.robot._urdf_tree import (
    _MOVABLE,
    _chain_kids,
    _movable_below,
    _origin,
    _plain,
    _tree,
)
from kinecal.typing import Float, Pose

__all__ = ["LikeExport", "like_urdf"]

# The vendor's file against the model's nominal robot (axis lines at the zero pose, the
# vendor-to-model link transforms on random poses) [m, rad]: above _REFUSE another robot;
# between _SAME and _REFUSE the same robot described with other numbers (a data sheet's
# rounding), accepted with a warning: the FK stays exact, the meshes sit that far off.
_SAME = 1e-5
_REFUSE = 1e-3


@dataclass(frozen=True)
class LikeExport:
    """The written document and what changed.

    Attributes
    ----------
    text : the URDF document.
    root, tips : root link; marker label -> calibrated tool link.
    tip : the vendor's tip link (the end of the unbranched chain below the last moving
        link), parent of the tool links.
    joints : vendor names of the movable joints, in chain order.
    moved_mm, turned_deg : largest change of a joint origin's position and rotation.
    mismatch_mm : how far the vendor's nominal robot is from the model's (axis lines,
        link motion; mm or mrad); above 0.01 the CLI warns.
    check_m : largest FK difference to the model on random poses, read back [m].
    origins : vendor joint name -> its calibrated origin (4, 4).
    """

    text: str
    root: str
    tips: dict[str, str]
    tip: str
    joints: tuple[str, ...]
    moved_mm: float
    turned_deg: float
    mismatch_mm: float
    check_m: float
    origins: dict[str, Pose]


def _vendor_path(
    root_el: ET.Element, src: str, n: int, names: tuple[str, ...] = ()
) -> tuple[str, list[ET.Element], list[int]]:
    """Root link, the joints from it down to the last movable joint of the one movable
    chain, and the positions of the movable ones in that list. Where the tree branches
    (two arms on a frame), the branch holding the model's next joint by name (``names``,
    as import-urdf keeps them)."""
    links, by_child, children = _tree(root_el, src)
    roots = sorted(lk for lk in links if lk not in by_child)

    def movable_below(link: str) -> int:
        """Driven joints below ``link`` (a mimic joint off the chain is a passive
        linkage, a balancer's cylinder, or a gripper's finger)."""
        return len(_movable_below(link, children, by_child, driven=True))

    def by_name(kids: list[str], k: int) -> list[str]:
        """``kids`` narrowed to the one holding the model's joint ``k`` by name."""
        if k >= len(names):
            return kids
        hit = [
            c
            for c in kids
            if (c in by_child and names[k] == by_child[c].get("name"))
            or names[k] in _movable_below(c, children, by_child)
        ]
        return hit if len(hit) == 1 else kids

    with_joints = by_name([lk for lk in roots if movable_below(lk)], 0)
    if len(with_joints) != 1:
        raise ConfigError(
            f"{src}: expected one tree with movable joints; found "
            f"{len(with_joints)} ({', '.join(map(repr, with_joints)) or 'none'})."
        )
    root = with_joints[0]
    path: list[ET.Element] = []
    link = root
    while movable_below(link):
        kids = _chain_kids(link, children, by_child, sum(map(_moves, path)))
        if kids is None or (len(kids) > 1 and sum(map(_moves, path)) == n):
            break  # a gripper's fingers (or a hand's) below the robot's n joints
        kids = by_name(kids, sum(map(_moves, path)))
        if len(kids) > 1:
            raise ConfigError(
                f"{src}: the chain branches at link {link!r} into "
                f"{', '.join(map(repr, kids))}, each with movable joints; expected one "
                "serial chain (a gripper's fingers? remove them from the copy)."
            )
        link = kids[0]
        path.append(by_child[link])
    for j in path:
        kind = j.get("type", "")
        if kind != "fixed" and kind not in _MOVABLE:
            raise ConfigError(
                f"{src}: joint {j.get('name')!r} has type {kind!r}; expected fixed, "
                "revolute, continuous or prismatic joints in the robot's chain."
            )
        if _moves(j) and j.find("mimic") is not None:
            raise ConfigError(
                f"{src}: joint {j.get('name')!r} is a mimic joint; --like needs "
                "independent joints (the URDF joints take the kinematic angles): use the "
                "vendor's file without the mimic joints."
            )
    movable = [k for k, j in enumerate(path) if _moves(j)]
    if len(movable) != n:
        found = ", ".join(repr(path[k].get("name")) for k in movable)
        raise ConfigError(
            f"{src}: the chain {root} -> {link} has {len(movable)} movable joints "
            f"({found}); the model's robot has {n}. Expected the URDF of the calibrated "
            "robot."
        )
    return root, path, movable


@dataclass(frozen=True)
class _VendorChain:
    """The vendor's joints from the root to the last movable one: ``path`` (joint
    elements), ``movable`` (indices into it), their names, types and axes (in the child
    frame), the fixed origins as written and as import-urdf reads them (``exact``: a
    rounded pi/2 exact; the link motion is compared with the model's through them, the
    written file keeps its own)."""

    root: str
    path: list
    movable: list
    names: tuple
    kinds: list
    axes: dict
    origins: list
    exact: list

    @classmethod
    def of(cls, root_el: ET.Element, src: str, robot, added: tuple) -> _VendorChain:
        """The chain of ``robot``'s joints in the vendor's tree (``added``: the link
        names export-urdf adds, which must be new)."""
        n = robot.n_joints
        root, path, movable = _vendor_path(
            root_el, src, n, tuple(j.name for j in robot.joints)
        )
        names = tuple(path[k].get("name", "?") for k in movable)
        kinds = [path[k].get("type", "") for k in movable]
        for i, (kind, pris) in enumerate(zip(kinds, robot.prismatic)):
            if (kind == "prismatic") != bool(pris):
                raise ConfigError(
                    f"{src}: joint {names[i]!r} is {kind}; joint {i + 1} of "
                    f"{robot.name} is {'prismatic' if pris else 'revolute'}."
                )
        for k, name, kind in zip(movable, names, kinds):  # kept in the copy: checked
            lim = path[k].find("limit")
            if kind != "continuous" and lim is None:  # as import-urdf (and urdfdom)
                raise ConfigError(
                    f"{src}: joint {name!r} ({kind}): no <limit>; expected <limit "
                    "lower=.. upper=..> (a joint without limits is type 'continuous')."
                )
            if kind != "continuous" and lim is not None:
                lo, hi = _limits(lim, f"{src}: joint {name!r} limit")
                check_travel(
                    lo, hi, kind == "prismatic", f"{src}: joint {name!r} limit", ""
                )
        where = [f"{src}: joint {j.get('name')!r} origin" for j in path]
        origins = [_origin(j, w) for j, w in zip(path, where)]
        exact = [_origin(j, w, quarters=True) for j, w in zip(path, where)]
        axes = {k: axis_of(path[k], f"{src}: joint {names[i]!r}")
                for i, k in enumerate(movable)}  # fmt: skip
        for existing in {el.get("name") for el in root_el.findall("link")}:
            if existing is not None and existing in added:
                raise ConfigError(
                    f"{src}: already has a link {existing!r}; choose another name "
                    "(--tool-link / --user-link)."
                )
        return cls(root, path, movable, names, kinds, axes, origins, exact)

    def frames(self, theta: Float, org: list[Pose]) -> list[Pose]:
        """Child link frames of the movable joints at ``theta``, in the root frame."""
        T, out, i = np.eye(4), [], 0
        for k in range(len(self.path)):
            T = T @ org[k]
            if k in self.axes:
                T = T @ motion(self.kinds[i], self.axes[k], float(theta[i]))
                out.append(T)
                i += 1
        return out


def _refuse_motion(errs: list[float], names: tuple, robot, src: str) -> None:
    """Refuse a vendor file whose links move otherwise than the model's joints (the
    link transforms ``errs`` [m] of one random pose)."""
    for i, err in enumerate(errs):
        if err > _REFUSE:
            n = robot.n_joints
            raise ConfigError(
                f"{src}: link of joint {names[i]!r} moves differently from joint "
                f"{i + 1} of {robot.name} ({err * 1e3:.3f} mm apart on a random "
                "pose); expected the URDF of the same robot"
                + (
                    ", its joints taking the kinematic angles (theta = C q_ctrl, "
                    "FANUC joint_3 = J3 + J2)."
                    if not np.array_equal(robot.coupling, np.eye(n))
                    else "."
                )
            )


def _moves(j: ET.Element) -> bool:
    return j.get("type", "") in _MOVABLE


def like_urdf(
    cal,
    vendor: str | Path,
    *,
    set_label: str | None = None,
    tool_link: str = "calibrated_tool",
    user_link: str | None = None,
    comments: list[str] | None = None,
    text: str | None = None,
    tip_note: bool = False,
) -> LikeExport:
    """The vendor's URDF with the calibrated joint origins (module docstring).

    Parameters
    ----------
    cal : CalibratedModel.
    vendor : the vendor's URDF (untrusted: every problem is a :class:`ConfigError`).
    set_label : the set whose user frame ``user_link`` is.
    tool_link : name of the calibrated tool link (a fixed child of the tip link);
        ``<tool_link>_<marker>`` per marker when the model has several.
    user_link : when given, a new root link of this name, the measurement frame of the
        set, so that FK user_link -> tool_link is the model's tool pose.
    comments : lines of a comment put before the ``<robot>`` element.
    text : the document itself (``vendor`` then only names it in messages).
    tip_note : add the line ``kinecal tip link: <tip>`` to the comment (read by
        :func:`kinecal.robot.robot_from_urdf`).
    """
    from kinecal.compensation import export_chain

    check_link_names(tool_link, user_link)
    src = str(vendor)
    raw, root_el = read_vendor(vendor, text)
    model = cal.model
    robot = model.robot
    n = model.n_joints
    C = robot.coupling
    vc = _VendorChain.of(root_el, src, robot, (tool_link, user_link))
    path, movable, names, axes = vc.path, vc.movable, vc.names, vc.axes
    nominal = type(cal)(
        model, model.nominal.copy(), np.full(model.size, np.nan), ["fixed"] * model.size
    )
    ch_nom = export_chain(nominal, set_label=set_label)
    ch_cal = export_chain(cal, set_label=set_label)
    rng = np.random.default_rng(1)
    B, H, resid = _match(vc, ch_nom, robot, src, rng)
    # Calibrated frames in the vendor root; new origins along the path.
    T_root_user = B @ np.linalg.inv(ch_cal.T_user_base)
    U_cal = [B @ J @ h for J, h in zip(_model_frames(ch_cal, np.zeros(n), C), H)]
    new, moved, turned = new_origins(vc.origins, U_cal, axes)
    for k in movable:
        raw = _set_origin(raw, path[k].get("name", ""), new[k], src)
    # The calibrated tool frame(s) and the user frame.
    # The tip: down from the last moving link while the chain does not branch.
    tip, T_last_tip = _tip_link(root_el, path[movable[-1]], src)
    tips, extra = _tool_links(
        ch_cal, model.spec.markers, tool_link, tip,
        np.asarray(np.linalg.inv(U_cal[-1] @ T_last_tip) @ T_root_user, np.float64), n,
    )  # fmt: skip
    top = vc.root
    if user_link is not None:
        extra += fixed_xml(user_link, user_link, vc.root, np.linalg.inv(T_root_user))
        top = user_link
    if tip_note:
        comments = [
            *(comments or []),
            f"kinecal tip link: {tip} (the robot's flange, for import-urdf and --robot).",
        ]
    text = _with_additions(raw, extra, comments, src)
    # Read back: FK of the written file against the model's kinematic part.
    T_top_user = np.eye(4) if user_link is not None else T_root_user
    check = _check(text, src, cal, set_label, tips, top, T_top_user, rng)
    return LikeExport(
        text,
        top,
        tips,
        tip,
        names,
        moved * 1e3,
        float(np.degrees(turned)),
        resid * 1e3,
        check,
        {path[k].get("name", ""): new[k] for k in movable},
    )


def _model_frames(ch, theta: Float, C: Float) -> list[Pose]:
    """Joint frames link1..linkN of an exported chain at kinematic angles ``theta``, in
    the robot base frame (``C`` the robot's coupling: the chain takes q_ctrl)."""
    q = (np.linalg.inv(C) @ theta)[None]
    Tb = np.linalg.inv(ch.T_user_base)
    return [Tb @ ch.fk(q, f"link{i + 1}")[0] for i in range(C.shape[0])]


def _match(
    vc: _VendorChain, ch_nom, robot, src: str, rng: np.random.Generator
) -> tuple[Pose, list[Pose], float]:
    """(B, H, resid): the model's robot base in the vendor's root (by the axis lines of
    the zero pose), the constant transform H_i from each nominal joint frame to the
    vendor's link frame, and the largest mismatch [m, rad] over the zero pose and 8
    random ones; a vendor file of another robot is refused."""
    n, C = robot.n_joints, robot.coupling
    zero = np.zeros(n)
    J0 = _model_frames(ch_nom, zero, C)
    U0 = vc.frames(zero, vc.exact)
    dirs_v = np.array([U[:3, :3] @ vc.axes[k] for U, k in zip(U0, vc.movable)])
    B, resid = place_base(J0, U0, dirs_v, vc.kinds, src)
    if resid > _REFUSE:
        raise ConfigError(
            f"{src}: the joint axes of this URDF are {resid * 1e3:.3f} mm (or "
            f"{np.degrees(resid):.3f} deg) from the nominal axes of {robot.name}, the "
            "model's robot; expected the URDF of the same robot (joints in the same "
            "order, turning the same way)."
        )
    H = [
        exact_link(np.linalg.inv(B @ J) @ U, vc.axes[k], kind)
        for J, U, k, kind in zip(J0, U0, vc.movable, vc.kinds)
    ]
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    for theta in rng.uniform(lim[:, 0], lim[:, 1], (8, n)) @ C.T:
        pairs = zip(_model_frames(ch_nom, theta, C), vc.frames(theta, vc.exact))
        errs = [float(np.abs(np.linalg.inv(B @ J) @ U - h).max()) for (J, U), h
                in zip(pairs, H)]  # fmt: skip
        resid = max(resid, *errs)
        _refuse_motion(errs, vc.names, robot, src)
    return B, H, resid


def _with_additions(
    raw: str, extra: list[str], comments: list[str] | None, src: str
) -> str:
    """The vendor's text with the added links before ``</robot>`` and the comment,
    both in the file's own line ends."""
    end = raw.rfind("</robot>")
    if end < 0:
        raise ConfigError(f"{src}: no closing </robot> tag.")
    eol = "\r\n" if "\r\n" in raw else "\n"  # the vendor's line ends
    text = raw[:end] + "".join(extra).replace("\n", eol) + raw[end:]
    return with_comment(text, comments, eol) if comments else text


def _tip_link(root_el: ET.Element, last: ET.Element, src: str) -> tuple[str, Pose]:
    """(tip, T_last_tip): down from the last moving joint's child link while the chain
    does not branch, and the fixed transform from that child to the tip."""
    tip = last.find("child").get("link", "")  # type: ignore[union-attr]
    _, by_child, children = _tree(root_el, src)
    T_last_tip = np.eye(4)
    while len(children.get(tip, [])) == 1:
        child = children[tip][0]
        j = by_child[child]
        if _moves(j):  # pragma: no cover - _vendor_path stops at the last movable
            break
        T_last_tip = T_last_tip @ _origin(j, f"{src}: joint {j.get('name')!r} origin")
        tip = child
    return tip, T_last_tip


def _tool_links(
    ch_cal, markers: tuple, tool_link: str, tip: str, T_tip_user: Pose, n: int
) -> tuple[dict[str, str], list[str]]:
    """({marker: link name}, XML lines) of the calibrated tool links: fixed children of
    the tip at the model's tool pose (``T_tip_user`` the user frame in the tip's at the
    zero pose)."""
    q0 = np.zeros((1, n))
    tips: dict[str, str] = {}
    extra: list[str] = []
    for label in markers:
        name = tool_link if len(markers) == 1 else f"{tool_link}_{label or 'default'}"
        name = "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in name)
        O = T_tip_user @ ch_cal.fk(q0, ch_cal.tips[label])[0]
        extra += fixed_xml(name, tip, name, O)
        tips[label] = name
    return tips, extra


def _set_origin(raw: str, name: str, O: Pose, src: str) -> str:
    """``raw`` with the ``<origin>`` of joint ``name`` replaced by ``O`` (the rest of the
    document byte for byte as it was). The robot's joint is the ``<joint>`` with a
    ``type``, outside comments (a ``<transmission>`` or ``<ros2_control>`` names joints
    too)."""
    pat = re.compile(
        r"<joint\b([^>]*)\bname\s*=\s*([\"'])"
        + re.escape(name)
        + r"\2([^>]*)>(.*?)</joint\s*>",
        re.S,
    )
    comments = [  # and CDATA sections (a gazebo plugin's text)
        c.span() for c in re.finditer(r"<!--.*?-->|<!\[CDATA\[.*?\]\]>", raw, re.S)
    ]
    hits = [
        m
        for m in pat.finditer(raw)
        if re.search(r"\btype\s*=", m.group(1) + m.group(3))
        and not any(a <= m.start() < b for a, b in comments)
    ]
    if len(hits) != 1:
        raise ConfigError(
            f"{src}: cannot find the element of joint {name!r} in the text "
            f'({len(hits)} matches); expected one <joint name="{name}" type=...>...'
            "</joint>."
        )
    m = hits[0]
    new = (
        f'<origin xyz="{" ".join(num(v) for v in O[:3, 3])}" '
        f'rpy="{" ".join(num(v) for v in matrix_to_rpy(O[:3, :3]))}"/>'
    )
    body = m.group(4)
    o = re.search(r"<origin\b[^>]*?/>|<origin\b[^>]*>.*?</origin\s*>", body, re.S)
    if o is not None:
        body = body[: o.start()] + new + body[o.end() :]
    else:
        body = ("\r\n" if "\r\n" in raw else "\n") + f"    {new}" + body
    a, b = m.span(4)
    return raw[:a] + body + raw[b:]


def _check(text, src, cal, set_label, tips, top, T_top_user, rng) -> float:
    """Largest difference [m] between the written file's FK (``top`` -> tool links) and
    the model's kinematic part (in ``top``) on random poses."""
    from kinecal.compensation import kinematic_params
    from kinecal.models import ModelInputs

    model = cal.model
    robot = model.robot
    n = model.n_joints
    _, by_child, _ = _tree(_plain(ET.fromstring(text.lstrip("\ufeff"))), src)
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    q = rng.uniform(lim[:, 0], lim[:, 1], (16, n))
    theta = q @ robot.coupling.T
    s = 0 if set_label is None else model.spec.sets.index(set_label)
    x = kinematic_params(cal)
    worst = 0.0
    for m, label in enumerate(model.spec.markers):
        chain = []
        link = tips[label]
        while link in by_child:
            chain.append(by_child[link])
            link = by_child[link].find("parent").get("link", "")  # type: ignore[union-attr]
        if link != top:  # pragma: no cover - a defect, not a user error
            raise RuntimeError(f"export-urdf --like: {tips[label]} is not below {top}.")
        chain.reverse()
        N = len(q)
        inp = ModelInputs.make(q, set_index=np.full(N, s), marker_index=np.full(N, m))
        out = model.evaluate(x, inp, orientation=True)
        for r in range(N):  # a check on 16 poses, not a hot path
            T, i = np.eye(4), 0
            for j in chain:
                T = T @ _origin(j, src)
                if _moves(j):
                    T = T @ motion(j.get("type", ""), axis_of(j, src), theta[r, i])
                    i += 1
            want = np.eye(4)
            want[:3, :3], want[:3, 3] = out.R_user_cam[r], out.p_user[r]
            worst = max(worst, float(np.abs(T - T_top_user @ want).max()))
    return worst
