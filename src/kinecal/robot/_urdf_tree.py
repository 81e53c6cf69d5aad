"""A URDF's elements for :mod:`kinecal.robot._urdf` and ``export-urdf --like``: numbers,
joint origins, the tree of links and joints (checked: no loop, no cycle) and the serial
chain in it (passive linkages and a gripper's fingers left aside)."""

from __future__ import annotations

import re
import warnings
import xml.etree.ElementTree as ET

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import rpy_to_matrix

__all__: list[str] = []

_MOVABLE = ("revolute", "continuous", "prismatic")
_HOW = (
    "import-urdf FILE --base LINK --tip LINK --out robot.yaml, then --robot robot.yaml"
)


def _floats(text: str | None, n: int, where: str) -> np.ndarray:
    try:
        v = np.array([float(t) for t in (text or "").split()])
    except ValueError:
        raise ConfigError(f"{where}: expected {n} numbers; got {text!r}.") from None
    if v.shape != (n,) or not np.all(np.isfinite(v)):
        raise ConfigError(f"{where}: expected {n} finite numbers; got {text!r}.")
    return v


def _exact_quarters(text: str, rpy: np.ndarray) -> np.ndarray:
    """``rpy`` with the angles written as a multiple of pi/2 rounded to their printed
    decimals (4 to 9 of them: 1.5708, 3.1416, -1.570796327, as CAD exporters write) read
    as that exact multiple: a rounded pi/2 tilts an axis by up to 5e-5 rad, which turns
    two parallel axes into axes meeting kilometres away."""
    out = rpy.copy()
    for i, tok in enumerate(text.split()):
        m = re.fullmatch(r"[+-]?\d*\.(\d{4,9})", tok)
        k = round(rpy[i] / (np.pi / 2))
        if m and k and float(f"{k * np.pi / 2:.{len(m.group(1))}f}") == rpy[i]:
            out[i] = k * np.pi / 2
    return out


# A fixed rotation needs no angle beyond a turn; a URDF's angles are radians, and one
# beyond (90, 180: 14 and 29 turns) is a degree typed as a radian (it read as another
# rotation without a word). A turn rounded up (6.2832) is still one.
_TURN = 2 * np.pi + 0.01


def _check_turn(rpy: np.ndarray, where: str) -> None:
    big = np.abs(rpy) > _TURN
    if big.any():
        v = float(rpy[np.argmax(big)])
        raise ConfigError(
            f"{where}: {v:g} rad; expected angles in radians within +-{_TURN:.4g} "
            "(a turn; degrees given as radians?)."
        )


def _origin(joint: ET.Element, where: str, *, quarters: bool = False) -> np.ndarray:
    """The joint's origin; ``quarters``: rounded multiples of pi/2 made exact (import,
    :func:`_exact_quarters`)."""
    T = np.eye(4)
    el = joint.find("origin")
    if el is not None:
        text = el.get("rpy", "0 0 0")
        rpy = _floats(text, 3, f"{where} rpy")
        _check_turn(rpy, f"{where} rpy")
        T[:3, :3] = rpy_to_matrix(_exact_quarters(text, rpy) if quarters else rpy)
        T[:3, 3] = _floats(el.get("xyz", "0 0 0"), 3, f"{where} xyz")
    return T


def _once(el: ET.Element, tags: tuple[str, ...], what: str, src: str) -> None:
    """Refuse an element given twice where URDF allows one (the first was taken, the
    second ignored: an edit appended below the original changed nothing)."""
    for tag in tags:
        if len(el.findall(tag)) > 1:
            raise ConfigError(
                f"{src}: {what} has {len(el.findall(tag))} <{tag}> elements; expected "
                "at most one."
            )


def _tree(
    root: ET.Element, src: str
) -> tuple[set[str], dict[str, ET.Element], dict[str, list[str]]]:
    """Links, the joint above each link and the children of each link, checked to form
    trees: every joint's links defined, no link below two joints (a closed loop), no
    cycle."""
    links: set[str] = set()
    for k, el in enumerate(root.findall("link")):
        name = el.get("name", "")
        if not name.strip():  # (urdfdom refuses it; joints without links matched it)
            raise ConfigError(
                f"{src}: link {k + 1} (in file order) has no name; expected "
                '<link name="...">.'
            )
        if name in links:
            raise ConfigError(
                f"{src}: link {name!r} is defined twice; expected unique names."
            )
        links.add(name)
        _once(el, ("inertial",), f"link {name!r}", src)
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
        _once(
            j,
            ("parent", "child", "origin", "axis", "limit", "mimic"),
            f"joint {jn!r}",
            src,
        )
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise ConfigError(f"{src}: joint {jn!r} lacks parent or child.")
        p, c = parent.get("link", ""), child.get("link", "")
        for role, name in (("parent", p), ("child", c)):
            if not name:
                raise ConfigError(
                    f"{src}: joint {jn!r}: <{role}> names no link; expected "
                    f'<{role} link="..."/>.'
                )
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


def _movable_below(
    link: str, children: dict[str, list[str]], by_child, *, driven: bool = False
) -> list[str]:
    """Names of the movable joints in the tree below ``link`` (``driven``: only those
    without ``<mimic>``, the joints a controller drives)."""
    out, todo = [], [link]
    while todo:
        lk = todo.pop()
        for c in children.get(lk, []):
            j = by_child[c]
            if j.get("type", "") in _MOVABLE and not (
                driven and j.find("mimic") is not None
            ):
                out.append(j.get("name", "?"))
            todo.append(c)
    return out


def _chain_kids(link, children, by_child, so_far: int) -> list[str] | None:
    """The children of ``link`` the chain may go on to: those with driven joints at or
    below them. Side branches whose joints all mimic others (a balancer's cylinder and
    piston) are passive linkages and left, as fixed frames are. None when the chain ends
    at ``link`` on a gripper: after ``so_far`` >= 2 joints, several moving branches with
    at most two driven joints in all (fingers, most of them mimic joints)."""

    def driven(c: str) -> int:
        j = by_child[c]
        own = j.get("type", "") in _MOVABLE and j.find("mimic") is None
        return own + len(_movable_below(c, children, by_child, driven=True))

    kids = children.get(link, [])
    moving = [
        c
        for c in kids
        if by_child[c].get("type", "") in _MOVABLE
        or _movable_below(c, children, by_child)
    ]
    if len(moving) > 1 and so_far >= 2 and sum(map(driven, kids)) <= 2:
        return None
    return [c for c in kids if driven(c)]


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
        link, so_far = base, 0
        while children.get(link):
            kids = children[link]
            if len(kids) > 1:
                moving = _chain_kids(link, children, by_child, so_far)
                if moving is None:  # a gripper's fingers: the arm ends here
                    break
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
            so_far += by_child[link].get("type", "") in _MOVABLE
        tip = link
    for name, what in ((base, "base"), (tip, "tip")):
        if name not in links:
            some = sorted(links)
            raise ConfigError(
                f"{src}: no link {name!r} (--{what}); expected one of the file's "
                f"{len(some)} links: {', '.join(some[:12])}{' ...' * (len(some) > 12)}."
            )
    chain = []
    link = tip
    while link != base:
        if link not in by_child:
            raise ConfigError(
                f"{src}: link {tip!r} is not below link {base!r}; expected a tip link "
                f"below the base (the chain from {tip!r} goes up to {link!r})."
            )
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


def _plain(root: ET.Element) -> ET.Element:
    """``root`` with XML namespaces dropped from the tags (``<robot xmlns="...">``, as
    urdfdom reads them: by local name)."""
    for el in root.iter():
        if isinstance(el.tag, str) and el.tag.startswith("{"):
            el.tag = el.tag.split("}", 1)[1]
    return root
