"""Import a serial chain from a URDF file as a standard-DH robot description.

The joint axes of the chain, taken at the zero configuration in the root link's frame,
are lines in space; standard DH frames are placed on them (``z_{i-1}`` on joint i's axis,
pointing along the URDF axis so that positive joint values turn the same way, ``x_i``
along the common normal to the next axis) and the four DH numbers read off between
consecutive frames. The last DH frame is put on the last axis, level with the tip
link's origin; the tip link is the physical flange (``flange`` in the description).
DH frame 0 is the base link itself when the first axis is its z axis, else the base
link moved onto the first axis; that fixed transform is the description's ``T_base_0``
(``frame0``), so that poses stay in the base link's frame as in the URDF.

The links' inertials become the general link self-weight layout (``link_masses``): the
masses and centres of mass of every link between joint k and joint k + 1 (links hanging
from them by fixed joints included) are lumped into body k, its centre of mass given in
DH frame k. The lumped two-moment model of the paper (``self_weight``) stays null: the
general model covers any arm (7 axes, parallel shoulders, offset wrists, a prismatic
first joint). The URDF joint values are the controller values (no couplings).
"""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from kinecal.errors import ConfigError
from kinecal.robot._description import JointSpec, LinkMass, RobotDescription
from kinecal.robot._schema import (
    MAX_LENGTH_M,
    check_travel,
    dump_robot,
    robot_from_dict,
)
from kinecal.robot._urdf_joints import (
    declared_coupling,
    merge_mimics,
    mimic_of,
    rates_of,
)
from kinecal.robot._urdf_read import read_urdf
from kinecal.robot._urdf_tree import (
    _HOW,
    _MOVABLE,
    _chain,
    _floats,
    _origin,
    _plain,
    _tree,
)

__all__ = ["robot_from_urdf"]

_PARALLEL = 1e-9  # |sin| below which two axes count as parallel
_ON_AXIS = 1e-9  # [m]


def _limits(lim: ET.Element, where: str) -> tuple[float, float]:
    try:
        lo = float(lim.get("lower", "-inf"))
        hi = float(lim.get("upper", "inf"))
    except ValueError:
        raise ConfigError(
            f"{where}: expected numbers lower < upper; got lower={lim.get('lower')!r}, "
            f"upper={lim.get('upper')!r}."
        ) from None
    if np.isnan(lo) or np.isnan(hi) or not lo < hi:
        raise ConfigError(
            f"{where}: expected lower < upper; got lower={lo:g}, upper={hi:g}."
        )
    if not (np.isfinite(lo) and np.isfinite(hi)):  # (was: 'degrees given as radians?')
        raise ConfigError(
            f"{where}: expected finite limits; got lower={lo:g}, upper={hi:g} (a "
            "revolute joint without limits is type 'continuous')."
        )
    return lo, hi


def _on_z(p: np.ndarray, u: np.ndarray) -> bool:
    """Whether the line through ``p`` along ``u`` is the z axis (same direction)."""
    return bool(
        np.allclose(u, [0.0, 0.0, 1.0], atol=1e-9) and np.hypot(*p[:2]) <= _ON_AXIS
    )


def _inertial(link: ET.Element | None, where: str) -> tuple[float, np.ndarray] | None:
    """Mass [kg] and centre of mass (3,) [m] in the link frame, or None without one."""
    el = link.find("inertial") if link is not None else None
    if el is None:
        return None
    m_el = el.find("mass")
    if m_el is None:
        return None
    try:
        m = float(m_el.get("value", ""))
    except ValueError:
        raise ConfigError(
            f"{where} mass: expected a number; got {m_el.get('value')!r}."
        ) from None
    if not (np.isfinite(m) and 0 <= m <= 1e4):  # the robot file's bound (import)
        raise ConfigError(f"{where} mass: expected a mass 0..10000 kg; got {m:g}.")
    o = el.find("origin")
    c = (
        _floats(o.get("xyz", "0 0 0"), 3, f"{where} origin xyz")
        if o is not None
        else np.zeros(3)
    )
    return m, c


def _link_masses(
    root: ET.Element,
    src: str,
    placed: list[tuple[str, np.ndarray, int]],
    frames: list[np.ndarray],
) -> tuple[LinkMass, ...]:
    """Bodies 1..n from the inertials of the chain's links (``placed``: link name, pose
    at the zero configuration, body number) and of links fixed to them."""
    _, by_child, children = _tree(root, src)
    link_el = {el.get("name", ""): el for el in root.findall("link")}
    todo = list(placed)
    on_chain = {name for name, _, _ in placed}
    acc: dict[int, list[tuple[float, np.ndarray]]] = {}
    while todo:
        name, T, body = todo.pop()
        got = _inertial(link_el.get(name), f"{src}: link {name!r} inertial")
        if got is not None and body >= 1 and got[0] > 0:
            acc.setdefault(body, []).append((got[0], T[:3, :3] @ got[1] + T[:3, 3]))
        for c in children.get(name, []):
            j = by_child[c]
            if c in on_chain or j.get("type", "") != "fixed":
                continue  # the chain's next link, or a gripper's moving finger
            where = f"{src}: joint {j.get('name')!r}"
            todo.append((c, T @ _origin(j, where, quarters=True), body))
    out = []
    for k in sorted(acc):
        m = sum(mi for mi, _ in acc[k])
        p = sum(mi * pi for mi, pi in acc[k]) / m
        F = frames[k - 1]
        com = F[:3, :3].T @ (p - F[:3, 3])
        out.append(LinkMass(k, float(m), (float(com[0]), float(com[1]), float(com[2]))))
    return tuple(out)


def _angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> float:
    """Signed angle from unit vector ``a`` to ``b`` about unit ``axis``."""
    return float(np.arctan2(np.cross(a, b) @ axis, a @ b))


@dataclass
class _Walk:
    """The chain walked at the zero configuration, in the base link's frame: each movable
    joint's axis line (point, direction), its (name, kind, limits), mimic joints by
    index, rates by name, the fixed links above the first joint and every link placed
    (name, pose, body number), and the tip link's pose."""

    lines: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)
    specs: list[tuple[str, str, tuple[float, float]]] = field(default_factory=list)
    mimics: dict[int, tuple[str, float, float]] = field(default_factory=dict)
    rates: dict[str, tuple[float | None, float | None]] = field(default_factory=dict)
    fixed_above: list[tuple[str, np.ndarray]] = field(default_factory=list)
    placed: list[tuple[str, np.ndarray, int]] = field(default_factory=list)
    T_tip: np.ndarray = field(default_factory=lambda: np.eye(4))
    far: str = ""  # two axes meeting far away (:func:`_check_far`)


# The longest chain (sum of the joint origins' offsets, base to tip) a robot's URDF can
# plausibly hold [m]: the largest industrial arms reach about 4.7 m; a track or gantry's
# travel is a joint limit, not an origin. A file written in mm is 1000x longer.
_MAX_CHAIN_M = 50.0


def _check_metres(chain: list[ET.Element], src: str) -> None:
    """Refuse a chain whose origins add up to more than :data:`_MAX_CHAIN_M`: URDF
    lengths are metres (REP 103), and such a file is most likely in millimetres."""
    steps = [
        (j.get("name", "?"), float(np.linalg.norm(_origin(j, src)[:3, 3])))
        for j in chain
    ]
    total = sum(d for _, d in steps)
    if total > _MAX_CHAIN_M:
        name, longest = max(steps, key=lambda s: s[1])
        raise ConfigError(
            f"{src}: the joint origins add up to {total:.4g} m from base to tip (joint "
            f"{name!r}: {longest:.4g} m); expected a robot's size, at most "
            f"{_MAX_CHAIN_M:g} m: URDF lengths are metres, and this file looks like it "
            "is in millimetres (divide its lengths by 1000)."
        )


def _walk(chain: list[ET.Element], base: str, src: str) -> _Walk:
    """Axis lines and joint specifications of ``chain`` (see :class:`_Walk`)."""
    w = _Walk(placed=[(base, np.eye(4), 0)])
    T = np.eye(4)
    for j in chain:
        jn = j.get("name", "?")
        T = T @ _origin(j, f"{src}: joint {jn!r} origin", quarters=True)
        kind = j.get("type", "")
        child = j.find("child").get("link", "")  # type: ignore[union-attr]
        if kind not in _MOVABLE:
            if kind != "fixed":
                raise ConfigError(
                    f"{src}: joint {jn!r} has unsupported type {kind!r}; expected "
                    "revolute, continuous, prismatic or fixed joints in the chain "
                    "(kinecal calibrates serial arms)."
                )
            if not w.lines:
                w.fixed_above.append((child, T.copy()))
            w.placed.append((child, T.copy(), len(w.lines)))
            continue
        mim = j.find("mimic")
        if mim is not None:
            w.mimics[len(w.lines)] = mimic_of(mim, f"{src}: joint {jn!r} mimic")
        w.placed.append((child, T.copy(), len(w.lines) + 1))
        ax_el = j.find("axis")
        axis = _floats(
            ax_el.get("xyz") if ax_el is not None else "1 0 0",
            3,
            f"{src}: joint {jn!r} axis",
        )
        if not np.linalg.norm(axis) > 1e-9:
            raise ConfigError(
                f"{src}: joint {jn!r} axis: expected a non-zero direction; got "
                f"{axis.tolist()}."
            )
        axis = axis / np.linalg.norm(axis)
        lim = j.find("limit")
        lo, hi = -np.inf, np.inf
        if kind != "continuous":
            if lim is None:  # URDF: <limit> is required for revolute and prismatic
                raise ConfigError(
                    f"{src}: joint {jn!r} ({kind}): no <limit>; expected <limit "
                    f"lower=.. upper=.. [{'m' if kind == 'prismatic' else 'rad'}]> (a "
                    "joint without limits is type 'continuous')."
                )
            lo, hi = _limits(lim, f"{src}: joint {jn!r} limit")
            check_travel(lo, hi, kind == "prismatic", f"{src}: joint {jn!r} limit", "")
        w.rates[jn] = rates_of(lim, kind == "prismatic")
        w.lines.append((T[:3, 3].copy(), T[:3, :3] @ axis))
        kind_ = "prismatic" if kind == "prismatic" else "revolute"
        w.specs.append((jn, kind_, (lo, hi)))
    w.T_tip = T
    return w


def _next_frame(
    z_prev: np.ndarray,
    x_prev: np.ndarray,
    o_prev: np.ndarray,
    line: tuple[np.ndarray, np.ndarray] | None,
    T_tip: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The next DH frame's z, x and origin: on the next axis ``line`` (x along the
    common normal), or for the last frame (``line`` None) on the last axis, level with
    the tip link's origin."""
    if line is None:
        return z_prev, x_prev, o_prev + ((T_tip[:3, 3] - o_prev) @ z_prev) * z_prev
    q, z = line
    c = np.cross(z_prev, z)
    s = np.linalg.norm(c)
    if s > _PARALLEL:
        # x along the common normal; o where it meets the next axis.
        x = c / s
        A = np.column_stack([z_prev, -z])
        ts, *_ = np.linalg.lstsq(A, q - o_prev, rcond=None)
        o = q + ts[1] * z
        if (o - o_prev) @ x < -_ON_AXIS:
            x = -x  # either normal direction is DH; this one gives a > 0
        return z, x, o
    # Parallel axes: the common normal through the previous origin.
    w = q - o_prev
    w_perp = w - (w @ z_prev) * z_prev
    if np.linalg.norm(w_perp) > _ON_AXIS:
        x = w_perp / np.linalg.norm(w_perp)
    else:  # the same line: keep x
        x = x_prev
    return z, x, q + ((o_prev - q) @ z) * z


def _check_far(
    w: _Walk, i: int, d: float, a: float, alpha_deg: float, src: str
) -> bool:
    """Two axes a hair from parallel (an axis typed 0 1 0.001, a rounded angle) meet far
    away: a DH row longer than a robot (:data:`_MAX_CHAIN_M`) is named in a warning (fk
    --robot read d = -400 m without a word; a calibrated robot's axes may be that
    skewed), one beyond the robot file's bound refused (import-urdf wrote a file its
    reader refuses)."""
    if max(abs(d), abs(a)) <= _MAX_CHAIN_M:
        return False
    k = min(i + 1, len(w.specs) - 1)
    off = min(alpha_deg, abs(180.0 - alpha_deg))
    text = (
        f"{src}: the axes of joints {w.specs[k - 1][0]!r} and {w.specs[k][0]!r} are "
        f"{off:.3g} deg from parallel and their common normal lies far away (DH d = "
        f"{d:.4g} m, a = {a:.4g} m)"
    )
    if max(abs(d), abs(a)) > MAX_LENGTH_M:
        raise ConfigError(
            f"{text}; expected axes that are parallel or meet within "
            f"{MAX_LENGTH_M:g} m (a mistyped or rounded <axis> or rpy?)."
        )
    warnings.warn(f"{text}: a mistyped or rounded <axis> or rpy?", stacklevel=4)
    w.far = text
    return True


def _dh_joints(
    w: _Walk, offsets: np.ndarray, src: str
) -> tuple[list[JointSpec], list[np.ndarray], np.ndarray]:
    """Standard DH frames on the axis lines: the joints, the DH frames 1..n at the zero
    configuration and the flange in the last DH frame."""
    # Frame 0 = base frame. Frames 1..n-1 on the axes 2..n; frame n on the last axis.
    z_prev, x_prev, o_prev = np.array([0.0, 0, 1]), np.array([1.0, 0, 0]), np.zeros(3)
    joints: list[JointSpec] = []
    frames: list[np.ndarray] = []
    n = len(w.lines)
    far = False
    for i in range(n):
        nxt = w.lines[i + 1] if i + 1 < n else None
        z, x, o = _next_frame(z_prev, x_prev, o_prev, nxt, w.T_tip)
        d_vec = o - o_prev
        theta = _angle(x_prev, x, z_prev)
        d = float(d_vec @ z_prev)
        a = float(d_vec @ x)
        alpha = _angle(z_prev, z, x)
        resid = d_vec - d * z_prev - a * x
        if np.linalg.norm(resid) > 1e-7:
            raise ConfigError(
                f"{src}: could not place DH frame {i + 1} (residual "
                f"{np.linalg.norm(resid):.2e} m); the chain may need MDH."
            )
        if not far:  # (the first far row only: the next ones follow from it)
            far = _check_far(w, i, d, a, float(np.degrees(abs(alpha))), src)
        jname, jkind, jlim = w.specs[i]
        if jkind == "revolute":
            theta += offsets[i]
        joints.append(
            JointSpec(jname, theta, d, a, alpha, jkind, jlim, *w.rates[jname])
        )
        F = np.eye(4)
        F[:3, :3] = np.column_stack([x, np.cross(z, x), z])
        F[:3, 3] = o
        frames.append(F)
        z_prev, x_prev, o_prev = z, x, o
    return joints, frames, np.linalg.inv(frames[-1]) @ w.T_tip


def _read(path: str | Path, tip: str | None) -> tuple[ET.Element, str, str | None]:
    """The URDF's root element, its text and the tip link (kinecal's own export names
    its tip: the tool links hang below it)."""
    p = Path(path)
    text, root = read_urdf(p)  # (xacro, entities, encodings refused there)
    root = _plain(root)
    if root.tag != "robot":  # an SDF, a launch file: read as a robot without joints
        raise ConfigError(f"{p}: expected a URDF <robot> document; got <{root.tag}>.")
    if tip is None:
        m = re.search(r"kinecal tip link: (\S+)", text)
        if m is not None and any(
            el.get("name") == m.group(1) for el in root.iter("link")
        ):
            tip = m.group(1)
    return root, text, tip


def _declared_base(text: str, root: ET.Element) -> str | None:
    """The robot base link kinecal's own export names (its root is the measurement
    frame 'user'; the link on the first axis can be a turned frame of its own)."""
    m = re.search(r"kinecal base link: (\S+)", text)
    if m is None or not any(el.get("name") == m.group(1) for el in root.iter("link")):
        return None
    return m.group(1)


def _check_first_axis(w: _Walk, base: str, tip: str, src: str) -> None:
    """A chain of at least 2 joints whose first axis is the base link's z axis."""
    p1, u1 = w.lines[0]
    if not _on_z(p1, u1):
        raise ConfigError(
            f"{src}: the first joint axis must be the base link's z axis (DH frame 0 "
            f"sits on it); it is {np.round(u1, 6).tolist()} through "
            f"{np.round(p1, 6).tolist()}. Choose another base link ({_HOW})."
        )
    if len(w.lines) < 2:
        raise ConfigError(
            f"{src}: one movable joint ({w.specs[0][0]!r}) between {base!r} and "
            f"{tip!r}; expected a chain of at least 2 (another --base or --tip?)."
        )


def _base_on_first_axis(w: _Walk) -> str | None:
    """When the root is not on the first axis (kinecal's own export: the root is the
    measurement frame 'user'), the deepest fixed link above the first joint that is."""
    p1, u1 = w.lines[0]
    if _on_z(p1, u1):
        return None
    for link, T_root_link in reversed(w.fixed_above):
        Ti = np.linalg.inv(T_root_link)
        p_ = Ti[:3, :3] @ p1 + Ti[:3, 3]
        if w.specs[0][1] == "prismatic":  # a slide's line can pass anywhere
            p_ = np.zeros(3)
        if _on_z(p_, Ti[:3, :3] @ u1):
            return link
    return None


def _onto_first_axis(w: _Walk, base: str, src: str) -> np.ndarray:
    """When the first joint axis is not the base link's z axis (a vendor's base_link on
    the floor with the axis a few mm off, a first axis along -z): DH frame 0 is the base
    link turned so that its z axis is the first axis and moved onto it (to the axis
    point nearest its origin); ``w`` re-expressed in that frame, which is returned (in
    the base link: the description's ``T_base_0``, so that the robot base stays the
    base link), with a warning."""
    p1, u1 = w.lines[0]
    if _on_z(p1, u1):  # (a slide's line was put through the origin)
        return np.eye(4)
    # The shortest turn from z (or, for an axis pointing down, from -z after half a
    # turn about x: well conditioned both ways) to u1.
    flip = np.diag([1.0, 1.0, 1.0] if u1[2] >= 0 else [1.0, -1.0, -1.0])
    z = flip @ np.array([0.0, 0.0, 1.0])
    c, d = np.cross(z, u1), float(z @ u1)
    K = np.array([[0, -c[2], c[1]], [c[2], 0, -c[0]], [-c[1], c[0], 0]])
    R = (np.eye(3) + K + K @ K / (1.0 + d)) @ flip
    F0 = np.eye(4)
    F0[:3, :3], F0[:3, 3] = R, p1 - (p1 @ u1) * u1
    Fi = np.linalg.inv(F0)
    w.lines = [(Fi[:3, :3] @ p + Fi[:3, 3], Fi[:3, :3] @ u) for p, u in w.lines]
    w.placed = [(nm, Fi @ T, b) for nm, T, b in w.placed]
    w.fixed_above = [(nm, Fi @ T) for nm, T in w.fixed_above]
    w.T_tip = Fi @ w.T_tip
    warnings.warn(
        f"{src}: the first joint axis is not the z axis of link {base!r}; the "
        f"chain's base (DH frame 0) is {_moved(F0, base)[10:]}, kept as the robot's "
        f"frame0: the robot base stays link {base!r} (robot poses are given in its "
        "frame, as the URDF's; export-urdf --like writes the vendor's frames).",
        stacklevel=3,
    )
    return F0


def _moved(F0: np.ndarray, base: str) -> str:
    """'; frame0: <base> moved by ... mm and turned by ... deg' (empty when not
    moved)."""
    if np.array_equal(F0, np.eye(4)):
        return ""
    ang = np.degrees(np.arccos(np.clip((np.trace(F0[:3, :3]) - 1) / 2, -1, 1)))
    xyz = ", ".join(f"{v * 1e3 + 0.0:.6g}" for v in np.round(F0[:3, 3], 12))
    return f"; frame0: {base} moved by ({xyz}) mm and turned by {ang:.6g} deg"


def robot_from_urdf(
    path: str | Path,
    *,
    base: str | None = None,
    tip: str | None = None,
    name: str | None = None,
) -> RobotDescription:
    """A standard-DH description of the chain ``base`` .. ``tip`` of a URDF file.

    Parameters
    ----------
    path : URDF file.
    base, tip : link names; default the root link and the end of an unbranched chain.
    name : robot name; default the URDF's.

    Raises
    ------
    ConfigError
        Unreadable file, undefined links, a closed loop or a cycle, several separate
        trees without ``base``, branching chain without ``tip``, no movable joints, or
        a first joint axis that is not the base z axis (DH frame 0 must sit on it).

    Warns
    -----
    UserWarning
        The chain leaves some of the file's movable joints out (a gripper's fingers, or
        half of a chain broken in two).
    """
    src = str(Path(path))
    root, text, tip = _read(path, tip)
    declared = re.search(
        r"kinecal coupling \(theta = C q_ctrl\): (.*?)\s*(?:-->|$)", text, re.M
    )
    base = _declared_base(text, root) if base is None else base
    auto_base = base is None
    base, tip, chain = _chain(root, base, tip, src)
    w = _walk(chain, base, src)
    if not w.lines:
        raise ConfigError(f"{src}: no movable joint between {base!r} and {tip!r}.")
    _check_metres(chain, src)
    if w.mimics:  # bodies numbered by the independent joints (a mimic joint's link
        # belongs to the body of the joint it is merged with, or the one before)
        kept = np.cumsum([i not in w.mimics for i in range(len(w.lines))])
        w.placed = [(nm, Tp, int(kept[b - 1]) if b else 0) for nm, Tp, b in w.placed]
    w.lines, w.specs, C, offsets = merge_mimics(w.lines, w.specs, w.mimics, src)
    if declared is not None and not w.mimics:
        C = declared_coupling(declared.group(1), len(w.lines), src)
    if w.specs[0][1] == "prismatic":  # a slide has no axis position: put it through 0
        w.lines[0] = (np.zeros(3), w.lines[0][1])
    if auto_base and w.fixed_above:
        link = _base_on_first_axis(w)
        if link is None and not _on_z(*w.lines[0]):
            # no link on the first axis: the one the arm stands on, moved onto it
            link = w.fixed_above[-1][0]
        if link is not None:  # gravity stays the root's -z (a ceiling or wall mount)
            R_root_link = dict(w.fixed_above)[link][:3, :3]
            below = robot_from_urdf(path, base=link, tip=tip, name=name)
            g = R_root_link.T @ below.gravity
            return replace(below, gravity=np.where(abs(g) < 1e-9, 0.0, g))
    F0 = _onto_first_axis(w, base, src) if len(w.lines) > 1 else np.eye(4)
    _check_first_axis(w, base, tip, src)
    joints, frames, T_n_flange = _dh_joints(w, offsets, src)
    robot = RobotDescription(
        name=name or root.get("name") or Path(path).stem,
        convention="dh",
        joints=tuple(joints),
        coupling=C,
        T_n_flange=T_n_flange,
        gravity=np.array([0.0, 0.0, -9.80665]),  # the base link's -z (REP 103)
        self_weight=None,
        source=f"{src} (URDF {base} -> {tip}{_moved(F0, base)})",
        link_masses=_link_masses(root, src, w.placed, frames),
        T_base_0=F0,
    )
    # The robot file's checks, as import-urdf's YAML is read back (a coupling factor of
    # 1e300 in a mimic or kinecal coupling line passed --robot X.urdf).
    try:
        robot_from_dict(dump_robot(robot), source=src)
    except ConfigError as exc:  # a centre of mass in a DH frame 400 m away
        if not w.far:
            raise
        raise ConfigError(
            f"{w.far}: a mistyped or rounded <axis> or rpy? The DH description it "
            f"makes is refused: {str(exc).removeprefix(src + ': ')}"
        ) from None
    return robot
