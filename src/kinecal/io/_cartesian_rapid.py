"""RAPID Cartesian targets (:mod:`._cartesian_programs`): robtargets with the tool and
wobj of the moves that use them, ``Offs`` / ``RelTool`` offsets, tooldata and wobjdata."""

from __future__ import annotations

import re

import numpy as np

from kinecal.errors import DataError
from kinecal.io._cartesian_base import (
    _NUM,
    CartesianPoint,
    _bracket_list,
    _close,
    _line,
    _make,
    code_only,
    offset_targets,
    point_pose,
)
from kinecal.typing import Pose

__all__ = ["rapid_frames"]


def _rapid_offset(arg: str) -> tuple[str, tuple | None] | None:
    """A move's target argument -> (robtarget name, offset): offset None for the name
    itself, ('Offs', dx, dy, dz) [mm], ('RelTool', dx, dy, dz, rx, ry, rz) [mm, deg],
    or ('?',) for numbers that are not literals; None: not a robtarget (inline, an
    expression)."""
    if re.fullmatch(r"\w+", arg):
        return arg, None
    m = re.fullmatch(r"(Offs|RelTool)\s*\((.*)\)", arg, re.I | re.S)
    if m is None or not re.match(r"\s*\w+\s*,", m.group(2)):
        return None
    parts = [a.strip() for a in m.group(2).split(",")]
    if len(parts) != 4 or not re.fullmatch(r"\w+", parts[0]):
        return None
    rot = dict.fromkeys("xyz", 0.0)
    last = parts[3]
    for sw in re.finditer(rf"\\R([xyz])\s*:=\s*({_NUM})\s*", parts[3], re.I):
        rot[sw.group(1).lower()] = float(sw.group(2))
        last = last.replace(sw.group(0), "")
    nums = [*parts[1:3], last.strip()]
    if not all(re.fullmatch(_NUM, v) for v in nums) or "\\" in last:
        return parts[0], ("?",)
    d = tuple(float(v) for v in nums)
    if m.group(1).upper() == "OFFS":
        return parts[0], ("Offs", *d)
    return parts[0], ("RelTool", *d, rot["x"], rot["y"], rot["z"])


# Motion instructions -> places of their robtargets among the positional arguments (a
# circular move's CirPoint, then ToPoint; a search's ToPoint after Signal, SearchPoint).
_MOVES = {
    **dict.fromkeys(("MOVEL", "MOVEJ", "MOVELDO", "MOVEJDO", "MOVELSYNC", "MOVEJSYNC",
                     "MOVELAO", "MOVEJAO", "MOVELGO", "MOVEJGO", "TRIGGL", "TRIGGJ",
                     "TRIGGLIOS", "TRIGGJIOS", "ARCL", "ARCLSTART", "ARCLEND", "SPOTL",
                     "SPOTJ"), (0,)),
    **dict.fromkeys(("MOVEC", "MOVECDO", "MOVECSYNC", "MOVECAO", "MOVECGO", "TRIGGC",
                     "ARCC", "ARCCSTART", "ARCCEND"), (0, 1)),
    "SEARCHL": (2,),
    "SEARCHC": (2, 3),
}  # fmt: skip
_SET = ("DO", "AO", "GO")  # MoveLDO p, v, z, tool \\WObj:=w, signal, value
_MOVES_RE = re.compile(r"\b(" + "|".join(_MOVES) + r")\b([^;]*);", re.I)


def _positional(arg: str) -> str:
    """An argument without the optional ones written after it (``tool1\\WObj:=w``,
    ``v100 \\T:=5``, ``\\Conc``); a backslash inside (..) or [..] (``RelTool(p, 0, 0,
    0 \\Rz:=90)``) belongs to the argument."""
    depth = 0
    for i, ch in enumerate(arg):
        depth += ch in "(["
        depth -= ch in ")]"
        if ch == "\\" and depth == 0:
            return arg[:i].strip()
    return arg.strip()


def _rapid_uses(text: str) -> dict[str, list[tuple[str, str, tuple | None, int]]]:
    """robtarget name ('' for an inline one) -> [(tool, wobj, offset, position of the
    move)] of the move instructions that use it (offset: see :func:`_rapid_offset`;
    ('?', position) for a use inside another expression)."""
    uses: dict[str, list[tuple[str, str, tuple | None, int]]] = {}
    for m in _MOVES_RE.finditer(text):
        # Commas inside [..] (an inline target) or (..) (Offs(p10, 0, 0, 50)) do not
        # separate arguments; optional arguments (\WObj:=w, \Conc, \T:=5) are dropped,
        # the positional ones kept: the targets at their places, the tool last.
        args = [a.strip() for a in re.split(r",(?![^\[(]*[\])])", m.group(2))]
        pos = [p for p in (_positional(a) for a in args) if p]
        where = _MOVES[m.group(1).upper()]
        if len(pos) < where[-1] + (5 if m.group(1).upper()[-2:] in _SET else 3):
            continue
        # The tool is the last positional argument; a ...Sync move names a procedure
        # after it, a ...DO/AO/GO move a signal and its value.
        kind = m.group(1).upper()
        last = -2 if kind.endswith("SYNC") else -3 if kind[-2:] in _SET else -1
        tool = re.match(r"\s*(\w+)", pos[last])
        w = re.search(r"\\WObj\s*:=\s*(\w+)", m.group(2), re.I)
        pair = (tool.group(1) if tool else "tool0", w.group(1) if w else "wobj0")
        for a in (pos[i] for i in where):
            got = _rapid_offset(a)
            if got is None and a.startswith("["):
                got = ("", None)
            if got is None:  # robtargets inside an expression
                for name in re.findall(r"\b[A-Za-z_]\w*\b", a):
                    uses.setdefault(name, []).append((*pair, ("?",), m.start()))
                continue
            uses.setdefault(got[0], []).append((*pair, got[1], m.start()))
    return uses


def _rapid_pose(text: str, at: int) -> tuple[Pose, int]:
    """The pose ``[[x, y, z], [q1..q4]]`` whose first '[' is the first after ``at``, and
    the end of its quaternion list."""
    t_at = text.find("[", text.find("[", at) + 1)
    trans = _bracket_list(text, t_at)
    q_at = text.find("[", text.find("]", t_at) + 1)
    quat = _bracket_list(text, q_at)
    if len(trans) != 3 or len(quat) != 4:
        raise DataError(
            f"line {_line(text, at)}: expected a pose [[x, y, z], [q1, q2, q3, q4]]."
        )
    v = [float(text[a:b]) for a, b in trans + quat]
    try:
        return point_pose("rapid", tuple(v)), text.find("]", q_at)
    except DataError as exc:
        raise DataError(f"line {_line(text, at)}: {exc}") from None


def rapid_frames(text: str) -> tuple[dict[str, Pose | str], dict[str, Pose | str]]:
    """tooldata and wobjdata of a RAPID text: ({tool name: the tool in the flange frame},
    {wobj name: the object frame in the world frame}) (4, 4) [m], or why it cannot be
    used (str)."""
    text = code_only(text, "rapid")
    tools: dict[str, Pose | str] = {}
    wobjs: dict[str, Pose | str] = {}
    pat = r"\b(tooldata|wobjdata)\s+(\w+)\s*:=\s*\[\s*(TRUE|FALSE)\s*,"
    for m in re.finditer(pat, text, re.I):
        kind, name, hold = m.group(1).lower(), m.group(2), m.group(3).upper()
        if kind == "tooldata":
            T, _ = _rapid_pose(text, m.end())
            tools[name] = T if hold == "TRUE" else "a stationary tool (robhold FALSE)"
            continue
        head = re.match(
            r"\s*(TRUE|FALSE)\s*,\s*\"([^\"]*)\"\s*,", text[m.end() :], re.I
        )
        if head is None:
            raise DataError(f"line {_line(text, m.start())}: wobjdata {name}: expected "
                            "[robhold, ufprog, \"ufmec\", [uframe], [oframe]].")  # fmt: skip
        uf, end = _rapid_pose(text, m.end() + head.end())
        of, _ = _rapid_pose(text, end + 1)
        why = "held by the robot (robhold TRUE)" if hold == "TRUE" else ""
        why = why or ("moved by a mechanical unit" if head.group(2) else "")
        wobjs[name] = why or uf @ of
    return tools, wobjs


def _offset_text(name: str, off: tuple) -> str:
    if off[0] == "Offs":
        return f"Offs({name}; {off[1]:g}; {off[2]:g}; {off[3]:g})"
    return f"RelTool({name}; " + "; ".join(f"{v:g}" for v in off[1:]) + ")"


def _rapid_why(text: str, ulist: list) -> str:
    if not ulist:
        return "no move instruction uses it (its tool and wobj are unknown)"
    odd = [u for u in ulist if u[2] == ("?",)]
    if odd:
        return (f"a move uses it in an expression or with offsets that are not numbers "
                f"(line {_line(text, odd[0][3])}): one correction cannot serve both")  # fmt: skip
    if len({(t, w) for t, w, _, _ in ulist}) > 1:
        return "moves use it with different tools or wobjs"
    return ""


def _rapid_unseen(text: str, uses: dict, declared: set[str]) -> list[CartesianPoint]:
    """Targets counted and left: the elements of robtarget arrays (``CONST robtarget
    p{3} := [[..], ..]``: the moves index them), and robtargets that moves go to whose
    value this file does not hold (``VAR robtarget p;`` set by ``CRobT()`` or another
    instruction at run time, or declared in another module)."""
    out = []
    arr = r"\brobtarget\s+(\w+)\s*(\{[^}]*\})\s*:=\s*\["
    for m in re.finditer(arr, text, re.I):
        declared.add(m.group(1))
        end = _close(text, m.end() - 1)
        depth, n = 0, 0
        for i in range(m.end() - 1, end):
            depth += text[i] == "["
            depth -= text[i] == "]"
            if text[i] == "[" and depth == 2:  # an element
                n += 1
                out.append(CartesianPoint(
                    f"{m.group(1)}{{{n}}}", _line(text, i), ((i, i),), (), (), None, "",
                    "", why_not=f"an element of the robtarget array {m.group(1)}"
                    f"{m.group(2)}: its moves index it, not handled"))  # fmt: skip
    for name, ulist in uses.items():
        found = [u for u in ulist if u[2] != ("?",)]
        if name and name not in declared and found:
            at = found[0][3]
            out.append(CartesianPoint(
                name, _line(text, at), ((at, at),), (), (), None, "", "",
                why_not="its value is not in this file (set at run time, e.g. by "
                "CRobT(), or declared in another module)"))  # fmt: skip
    return out


def _rapid(text: str) -> list[CartesianPoint]:
    uses = _rapid_uses(text)
    out = []
    declared: set[str] = set()
    decl = r"\brobtarget\s+(\w+)\s*:=\s*\[|\b(Move(?:L|J))\s+\["
    for m in re.finditer(decl, text, re.I):
        open_at = m.end() - 1
        trans = _bracket_list(text, text.find("[", open_at + 1))
        q_at = text.find("[", text.find("]", open_at + 1) + 1)
        quat = _bracket_list(text, q_at)
        conf = _bracket_list(text, text.find("[", text.find("]", q_at) + 1))
        if len(trans) != 3 or len(quat) != 4 or len(conf) != 4:
            raise DataError(
                f"line {_line(text, m.start())}: robtarget {m.group(1) or m.group(2)}: "
                "expected [[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [...]]."
            )
        cf = [float(text[a:b]) for a, b in conf]
        if not all(np.isfinite(v) and v == int(v) and abs(v) < 1 << 16 for v in cf):
            raise DataError(f"line {_line(text, m.start())}: robtarget "
                            f"{m.group(1) or m.group(2)}: confdata {cf}: expected "
                            "whole numbers [cf1, cf4, cf6, cfx].")  # fmt: skip
        config = tuple(int(v) for v in cf)
        name = m.group(1) or m.group(2)
        if m.group(2):  # inline: the instruction's own tool and wobj
            rest = text[m.start() : text.find(";", m.start())]
            found = _rapid_uses(rest + ";").get("", [])
            pair = found[0][:2] if found else ("tool0", "wobj0")
            ulist: list[tuple[str, str, tuple | None, int]] = [(*pair, None, 0)]
        else:
            ulist = uses.get(name, [])
        why = _rapid_why(text, ulist)
        assigned = m.group(1) and re.search(
            rf"^[ \t]*{re.escape(name)}\b(?:\.\w+)*\s*:=", text, re.M | re.I
        )
        if assigned and not why:
            why = (f"the program assigns it (line {_line(text, assigned.start())}): the "
                   "value moved to is not the one declared")  # fmt: skip
        e_at = text.find("[", text.find("]", conf[-1][1]) + 1)
        if e_at < _close(text, open_at) and not why:
            ext = [float(text[a:b]) for a, b in _bracket_list(text, e_at)]
            if any(abs(v) < 8.9e9 for v in ext):
                why = ("external axes set in its extax (a track may carry the robot: "
                       "its base would move with them): not handled")  # fmt: skip
        tool, wobj = ulist[0][:2] if ulist and not why else ("", "")
        pt = _make(text, name, trans + quat, config=config, frame=wobj, tool=tool,
                   config_spans=tuple(conf), why_not=why)  # fmt: skip
        # Corrected for itself where a move goes to it, else for its first offset; every
        # other offset follows it (checked, counted).
        moves = [(u[2], u[3], _offset_text(name, u[2]) if u[2] else "")
                 for u in ulist if u[2] != ("?",)]  # fmt: skip
        out += offset_targets(text, pt, moves or [(None, 0, "")])
        declared.add(name)
    return out + _rapid_unseen(text, uses, declared)
