"""Import a serial chain from a URDF file as a standard-DH robot description.

The joint axes of the chain, taken at the zero configuration in the root link's frame,
are lines in space; standard DH frames are placed on them (``z_{i-1}`` on joint i's axis,
pointing along the URDF axis so that positive joint values turn the same way, ``x_i``
along the common normal to the next axis) and the four DH numbers read off between
consecutive frames. The last DH frame is put on the last axis, level with the tip
link's origin; the tip link is the physical flange (``flange`` in the description).

Only the geometry is imported: masses and the link self-weight layout are not, so the
description has ``self_weight: null`` (edit the YAML to add it). The URDF joint values
are the controller values (no couplings).
"""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import rpy_to_matrix
from kinecal.robot._description import JointSpec, RobotDescription

__all__ = ["robot_from_urdf"]

_MOVABLE = ("revolute", "continuous", "prismatic")
_HOW = (
    "import-urdf FILE --base LINK --tip LINK --out robot.yaml, then --robot robot.yaml"
)
_PARALLEL = 1e-9  # |sin| below which two axes count as parallel
_ON_AXIS = 1e-9  # [m]


def _floats(text: str | None, n: int, where: str) -> np.ndarray:
    try:
        v = np.array([float(t) for t in (text or "").split()])
    except ValueError:
        raise ConfigError(f"{where}: expected {n} numbers; got {text!r}.") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ConfigError(f"{where}: expected {n} finite numbers; got {text!r}.")
    return v


def _origin(joint: ET.Element, where: str) -> np.ndarray:
    T = np.eye(4)
    el = joint.find("origin")
    if el is not None:
        T[:3, :3] = rpy_to_matrix(_floats(el.get("rpy", "0 0 0"), 3, f"{where} rpy"))
        T[:3, 3] = _floats(el.get("xyz", "0 0 0"), 3, f"{where} xyz")
    return T


def _tree(
    root: ET.Element, src: str
) -> tuple[set[str], dict[str, ET.Element], dict[str, list[str]]]:
    """Links, the joint above each link and the children of each link, checked to form
    trees: every joint's links defined, no link below two joints (a closed loop), no
    cycle."""
    links: set[str] = set()
    for el in root.findall("link"):
        name = el.get("name", "")
        if name in links:
            raise ConfigError(
                f"{src}: link {name!r} is defined twice; expected unique names."
            )
        links.add(name)
    by_child: dict[str, ET.Element] = {}
    children: dict[str, list[str]] = {}
    joint_names: set[str] = set()
    for k, j in enumerate(root.findall("joint")):
        jn = j.get("name", "")
        if not jn:
            raise ConfigError(
                f"{src}: joint {k + 1} (in file order) has no name; expected "
                '<joint name="..." type="...">.'
            )
        if jn in joint_names:
            raise ConfigError(
                f"{src}: joint {jn!r} is defined twice; expected unique names."
            )
        joint_names.add(jn)
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise ConfigError(f"{src}: joint {jn!r} lacks parent or child.")
        p, c = parent.get("link", ""), child.get("link", "")
        for role, name in (("parent", p), ("child", c)):
            if name not in links:
                raise ConfigError(
                    f"{src}: joint {jn!r}: {role} link {name!r} is not defined; expected "
                    "the name of one of the file's <link> elements (misspelt?)."
                )
        if p == c:
            raise ConfigError(
                f"{src}: joint {jn!r} connects link {p!r} to itself; expected a joint "
                "between two links."
            )
        if c in by_child:
            raise ConfigError(
                f"{src}: link {c!r} is the child of joints {by_child[c].get('name')!r} and "
                f"{jn!r}: a closed kinematic loop; expected a tree (kinecal calibrates "
                "serial chains: remove the joint that closes the loop)."
            )
        by_child[c] = j
        children.setdefault(p, []).append(c)
    # Each link has at most one parent now; links no root reaches lie on a cycle.
    seen: set[str] = set()
    todo = [name for name in links if name not in by_child]
    while todo:
        name = todo.pop()
        seen.add(name)
        todo.extend(children.get(name, []))
    if len(seen) < len(links):
        cyc = sorted(links - seen)
        raise ConfigError(
            f"{src}: the joints form a cycle through links {', '.join(map(repr, cyc[:6]))}"
            f"{' ...' if len(cyc) > 6 else ''}; expected a tree (each link reached from "
            "a root link by one path)."
        )
    return links, by_child, children


def _movable_below(link: str, children: dict[str, list[str]], by_child) -> list[str]:
    """Names of the movable joints in the tree below ``link``."""
    out, todo = [], [link]
    while todo:
        lk = todo.pop()
        for c in children.get(lk, []):
            if by_child[c].get("type", "") in _MOVABLE:
                out.append(by_child[c].get("name", "?"))
            todo.append(c)
    return out


def _chain(
    root: ET.Element, base: str | None, tip: str | None, src: str
) -> tuple[str, str, list[ET.Element]]:
    links, by_child, children = _tree(root, src)
    if base is None:
        roots = sorted(lk for lk in links if lk not in by_child)
        trees = [lk for lk in roots if children.get(lk)]  # a lone link is no tree
        if not trees:
            raise ConfigError(f"{src}: no joints; expected a serial chain.")
        if len(trees) > 1:
            desc = ", ".join(
                f"{lk!r} ({len(_movable_below(lk, children, by_child))} movable joints)"
                for lk in trees
            )
            raise ConfigError(
                f"{src}: the joints form {len(trees)} separate trees, rooted at {desc}; "
                "expected one chain (a joint whose parent should be the end of the other "
                "tree names another link?), or name the base link of one tree ("
                + _HOW
                + ")."
            )
        base = trees[0]
    if tip is None:
        link = base
        while children.get(link):
            kids = children[link]
            if len(kids) > 1:
                moving = [
                    c
                    for c in kids
                    if by_child[c].get("type", "") in _MOVABLE
                    or _movable_below(c, children, by_child)
                ]
                if len(moving) == 1:  # the others are fixed frames: follow the chain
                    kids = moving
                elif not moving:  # fixed frames only (tools, markers): the chain ends
                    break
                else:
                    raise ConfigError(
                        f"{src}: the chain branches at link {link!r} "
                        f"({', '.join(kids)}); name the tip link ({_HOW})."
                    )
            link = kids[0]
        tip = link
    for name, what in ((base, "base"), (tip, "tip")):
        if name not in links:
            raise ConfigError(f"{src}: no link {name!r} ({what}).")
    chain = []
    link = tip
    while link != base:
        if link not in by_child:
            raise ConfigError(f"{src}: link {tip!r} is not below link {base!r}.")
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link", "")  # type: ignore[union-attr]
    chain.reverse()
    used = {j.get("name", "?") for j in chain if j.get("type", "") in _MOVABLE}
    others = [
        j.get("name", "?")
        for j in root.findall("joint")
        if j.get("type", "") in _MOVABLE and j.get("name", "?") not in used
    ]
    if others and used:
        warnings.warn(
            f"{src}: the chain {base} -> {tip} has {len(used)} of the file's "
            f"{len(used) + len(others)} movable joints; not in the robot: "
            f"{', '.join(others[:6])}{' ...' if len(others) > 6 else ''} (check --base "
            "and --tip).",
            stacklevel=3,
        )
    return base, tip, chain


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
    return lo, hi


def _declared_coupling(text: str, n: int, src: str) -> np.ndarray:
    """The coupling matrix of kinecal's line ``kinecal coupling (theta = C q_ctrl): J3 +=
    1.0 * J2; ...`` (its URDF joints take kinematic angles; the robot takes controller
    angles, as the data hold them)."""
    C = np.eye(n)
    for term in filter(None, (t.strip() for t in text.split(";"))):
        m = re.fullmatch(r"J(\d+) \+= (\S+) \* J(\d+)\.?", term)
        try:
            if m is None:
                raise ValueError(term)
            i, k, f = int(m.group(1)) - 1, int(m.group(3)) - 1, float(m.group(2))
        except ValueError:
            raise ConfigError(
                f"{src}: cannot read the coupling term {term!r} of the 'kinecal "
                "coupling' line; expected 'Ji += factor * Jk'."
            ) from None
        if not (0 <= i < n and 0 <= k < n and i != k and np.isfinite(f)):
            raise ConfigError(
                f"{src}: coupling term {term!r}: expected joints 1..{n}, two different "
                "ones, and a finite factor."
            )
        C[i, k] += f
    if abs(np.linalg.det(C)) < 1e-9:
        raise ConfigError(f"{src}: the declared joint coupling is singular.")
    return C


def _rates(lim: ET.Element | None) -> tuple[float | None, float | None]:
    """Velocity and effort of a ``<limit>`` (None where absent, not positive, or not a
    number: ROS-Industrial writes effort 0 for unknown)."""
    out: list[float | None] = []
    for key in ("velocity", "effort"):
        try:
            v = float(lim.get(key, "nan")) if lim is not None else np.nan
        except ValueError:
            v = np.nan
        out.append(v if np.isfinite(v) and v > 0 else None)
    return out[0], out[1]


def _on_z(p: np.ndarray, u: np.ndarray) -> bool:
    """Whether the line through ``p`` along ``u`` is the z axis (same direction)."""
    return bool(
        np.allclose(u, [0.0, 0.0, 1.0], atol=1e-9) and np.hypot(*p[:2]) <= _ON_AXIS
    )


def _mimic(el: ET.Element, where: str) -> tuple[str, float, float]:
    """(joint, multiplier, offset) of a ``<mimic>`` element."""
    name = el.get("joint", "")
    if not name:
        raise ConfigError(
            f'{where}: expected <mimic joint="NAME" .../>; no joint named.'
        )
    try:
        mult = float(el.get("multiplier", "1"))
        off = float(el.get("offset", "0"))
    except ValueError:
        raise ConfigError(
            f"{where}: expected numbers; got multiplier={el.get('multiplier')!r}, "
            f"offset={el.get('offset')!r}."
        ) from None
    if not (np.isfinite(mult) and np.isfinite(off)) or mult == 0.0:
        raise ConfigError(
            f"{where}: expected a finite non-zero multiplier and a finite offset; got "
            f"multiplier={mult:g}, offset={off:g}."
        )
    return name, mult, off


def _merge_mimics(lines, specs, mimics, src):
    """Joints that mimic another become a coupling: a mimic joint on the axis line of a
    neighbouring independent joint adds ``multiplier * q_other`` (and its offset) to
    that joint's kinematic angle (``theta = C q_ctrl``, FANUC J2/J3 as kinecal's
    ``--coupling mimic`` writes it). Returns the lines and specs of the independent
    joints, C and the angle offsets (n,)."""
    keep = [i for i in range(len(lines)) if i not in mimics]
    index = {specs[i][0]: k for k, i in enumerate(keep)}
    n = len(keep)
    C = np.eye(n)
    offsets = np.zeros(n)
    for i, (other, mult, off) in sorted(mimics.items()):
        name, kind, _ = specs[i]
        if other not in index:
            what = (
                "a mimic joint itself"
                if other in {s[0] for s in specs}
                else ("not a movable joint of the chain")
            )
            raise ConfigError(
                f"{src}: joint {name!r} mimics {other!r}, which is {what}; expected the "
                "name of an independent joint of the chain."
            )
        if kind != "revolute":
            raise ConfigError(
                f"{src}: joint {name!r} is a {kind} mimic joint; kinecal couples "
                "revolute joints only."
            )
        p, u = lines[i]
        host = None
        for k in (i + 1, i - 1):  # the independent neighbour on the same line
            if k in mimics or not 0 <= k < len(lines) or specs[k][1] != "revolute":
                continue
            q_, w = lines[k]
            d = p - q_
            if abs(abs(u @ w) - 1.0) < 1e-9 and np.linalg.norm(d - (d @ w) * w) < 1e-7:
                host = k
                sign = float(np.sign(u @ w))
                break
        if host is None:
            raise ConfigError(
                f"{src}: mimic joint {name!r} turns about its own axis; kinecal reads a "
                "mimic joint on the axis of the joint before or after it (a coupling "
                "such as FANUC J2/J3), not a separate linkage."
            )
        r = keep.index(host)
        C[r, index[other]] += sign * mult
        offsets[r] += sign * off
    if abs(np.linalg.det(C)) < 1e-9:
        raise ConfigError(f"{src}: the mimic joints make the joint coupling singular.")
    return [lines[i] for i in keep], [specs[i] for i in keep], C, offsets


def _angle(a: np.ndarray, b: np.ndarray, axis: np.ndarray) -> float:
    """Signed angle from unit vector ``a`` to ``b`` about unit ``axis``."""
    return float(np.arctan2(np.cross(a, b) @ axis, a @ b))


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
    p = Path(path)
    try:
        root = ET.parse(p).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{p}: cannot read URDF ({exc}).") from exc
    src = str(p)
    base_given = base
    text = p.read_text(errors="replace")
    declared = re.search(
        r"kinecal coupling \(theta = C q_ctrl\): (.*?)\s*(?:-->|$)", text, re.M
    )
    if tip is None:  # kinecal's own export names its tip (the tool links hang below it)
        m = re.search(r"kinecal tip link: (\S+)", text)
        if m is not None and any(
            el.get("name") == m.group(1) for el in root.iter("link")
        ):
            tip = m.group(1)
    base, tip, chain = _chain(root, base, tip, src)
    # Axis lines at the zero configuration, in the base link's frame.
    auto_base = base_given is None
    T = np.eye(4)
    lines: list[tuple[np.ndarray, np.ndarray]] = []
    specs: list[tuple[str, str, tuple[float, float]]] = []
    mimics: dict[int, tuple[str, float, float]] = {}
    rates: dict[str, tuple[float | None, float | None]] = {}
    fixed_above: list[tuple[str, np.ndarray]] = []
    for j in chain:
        jn = j.get("name", "?")
        T = T @ _origin(j, f"{src}: joint {jn!r} origin")
        kind = j.get("type", "")
        if kind not in _MOVABLE:
            if kind != "fixed":
                raise ConfigError(f"{src}: joint {jn!r} has unsupported type {kind!r}.")
            if not lines:
                child = j.find("child")
                assert child is not None
                fixed_above.append((child.get("link", ""), T.copy()))
            continue
        mim = j.find("mimic")
        if mim is not None:
            mimics[len(lines)] = _mimic(mim, f"{src}: joint {jn!r} mimic")
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
        if kind != "continuous" and lim is not None:
            lo, hi = _limits(lim, f"{src}: joint {jn!r} limit")
        rates[jn] = _rates(lim)
        lines.append((T[:3, 3].copy(), T[:3, :3] @ axis))
        specs.append((jn, "prismatic" if kind == "prismatic" else "revolute", (lo, hi)))
    if not lines:
        raise ConfigError(f"{src}: no movable joint between {base!r} and {tip!r}.")
    T_tip = T
    lines, specs, C, offsets = _merge_mimics(lines, specs, mimics, src)
    if declared is not None and not mimics:
        C = _declared_coupling(declared.group(1), len(lines), src)
    p1, u1 = lines[0]
    if specs[0][1] == "prismatic":  # a slide has no axis position: put it through 0
        p1 = np.zeros(3)
        lines[0] = (p1, u1)
    if not _on_z(p1, u1) and auto_base and fixed_above:
        # The root is not on the first axis (kinecal's own export: the root is the
        # measurement frame 'user'): the deepest link above the first joint that is.
        for link, T_root_link in reversed(fixed_above):
            Ti = np.linalg.inv(T_root_link)
            p_, u_ = Ti[:3, :3] @ p1 + Ti[:3, 3], Ti[:3, :3] @ u1
            if _on_z(p_, u_):
                return robot_from_urdf(path, base=link, tip=tip, name=name)
    if not _on_z(p1, u1):
        raise ConfigError(
            f"{src}: the first joint axis must be the base link's z axis (DH frame 0 "
            f"sits on it); it is {np.round(u1, 6).tolist()} through "
            f"{np.round(p1, 6).tolist()}. Choose another base link ({_HOW})."
        )
    if len(lines) < 2:
        raise ConfigError(
            f"{src}: one movable joint ({specs[0][0]!r}) between {base!r} and {tip!r}; "
            "expected a chain of at least 2 (another --base or --tip?)."
        )
    # Frame 0 = base frame. Frames 1..n-1 on the axes 2..n; frame n on the last axis.
    z_prev, x_prev, o_prev = (
        np.array([0.0, 0.0, 1.0]),
        np.array([1.0, 0.0, 0.0]),
        np.zeros(3),
    )
    joints: list[JointSpec] = []
    n = len(lines)
    for i in range(n):
        if i + 1 < n:
            q, z = lines[i + 1]
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
            else:
                # Parallel axes: the common normal through the previous origin.
                w = q - o_prev
                w_perp = w - (w @ z_prev) * z_prev
                if np.linalg.norm(w_perp) > _ON_AXIS:
                    x = w_perp / np.linalg.norm(w_perp)
                else:  # the same line: keep x
                    x = x_prev
                o = q + ((o_prev - q) @ z) * z
        else:
            z = z_prev
            x = x_prev
            o = o_prev + ((T_tip[:3, 3] - o_prev) @ z) * z
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
        jname, jkind, jlim = specs[i]
        if jkind == "revolute":
            theta += offsets[i]
        joints.append(JointSpec(jname, theta, d, a, alpha, jkind, jlim, *rates[jname]))
        z_prev, x_prev, o_prev = z, x, o
    F_n = np.eye(4)
    F_n[:3, :3] = np.column_stack([x_prev, np.cross(z_prev, x_prev), z_prev])
    F_n[:3, 3] = o_prev
    T_n_flange = np.linalg.inv(F_n) @ T_tip
    return RobotDescription(
        name=name or root.get("name") or p.stem,
        convention="dh",
        joints=tuple(joints),
        coupling=C,
        T_n_flange=T_n_flange,
        self_weight=None,
        source=f"{src} (URDF {base} -> {tip})",
    )
