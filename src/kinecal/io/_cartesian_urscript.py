"""URScript Cartesian targets (:mod:`._cartesian_programs`): poses in moves, pose
variables (``name = p[...]``, ``global``/``local``, Polyscope ``Name_p`` with ``Name_q``),
targets relative to features (``pose_trans(Plane_1, ...)``), the TCP of ``set_tcp``."""

from __future__ import annotations

import re
from dataclasses import replace

from kinecal.errors import DataError
from kinecal.io._cartesian_base import (
    CartesianPoint,
    _args,
    _bracket_list,
    _close,
    _line,
    _make,
    code_only,
    point_pose,
)
from kinecal.typing import Pose

__all__ = ["urscript_features"]

_ID = r"[A-Za-z_]\w*"
_NOT_SIX = "its pose is not six numbers p[x, y, z, rx, ry, rz]"


def _ur_target(text: str, a: int, b: int) -> tuple[str, str, int] | None:
    """A move's target expression ``text[a:b]`` -> (frame, 'p' or a variable name, the
    index of the pose literal's '[' or of the name); None: not a plain Cartesian
    target (a joint list, an expression)."""
    arg = text[a:b]
    call = re.match(r"(get_inverse_kin|pose_trans)\s*\(", arg)
    if call and _close(text, a + call.end() - 1) == b:
        inner = _args(text, a + call.end() - 1)
        if call.group(1) == "get_inverse_kin":
            return _ur_target(text, *inner[0])
        feat = re.fullmatch(_ID, text[inner[0][0] : inner[0][1]])
        if len(inner) != 2 or feat is None:
            return None
        got = _ur_target(text, *inner[1])
        return None if got is None or got[0] else (feat.group(0), got[1], got[2])
    if arg.startswith("p[") and _close(text, a + 1) == b:
        return "", "p", a + 1
    if re.fullmatch(_ID, arg):
        return "", arg, a
    return None


def _ur_tcps(text: str) -> list[tuple[int, str]]:
    """(position, TCP pose text 'p[...]', or '?<expression>' when not a literal)."""
    out = []
    for m in re.finditer(r"\bset_tcp\s*\(", text):
        args = _args(text, m.end() - 1)
        arg = text[args[0][0] : args[0][1]] if args else ""
        lit = arg.startswith("p[") and _close(text, args[0][0] + 1) == args[0][1]
        out.append((m.start(), arg if lit else "?" + arg))
    return out


def _ur_assignments(text: str) -> dict[str, list[tuple[int, int]]]:
    """Variable -> [(start of its assignment, index of its '[' or -1: not a pose
    literal)], for every ``[global|local] name = ...``."""
    out: dict[str, list[tuple[int, int]]] = {}
    pat = rf"^[ \t]*(?:(?:global|local)\s+)?({_ID})\s*=(?!=)\s*"
    for m in re.finditer(pat, text, re.M):
        lit = text.startswith("p[", m.end())
        out.setdefault(m.group(1), []).append((m.start(1), m.end() + 1 if lit else -1))
    return out


def urscript_features(text: str) -> dict[str, Pose | str]:
    """Variables used as the frame of ``pose_trans(FEATURE, target)`` in moves: their
    pose in the base frame (4, 4) [m] where the script assigns one literal pose, else
    why it cannot be used."""
    text = code_only(text, "urscript")
    assigned = _ur_assignments(text)
    out: dict[str, Pose | str] = {}
    for frame in {u[0] for u in _ur_uses(text)[0] if u[0]}:
        got = assigned.get(frame, [])
        if not got:
            continue  # not in the script: --uframe NAME=... may give it
        if len(got) > 1 or got[0][1] < 0:
            out[frame] = "assigned more than once or from an expression in the script"
            continue
        spans = _bracket_list(text, got[0][1])
        if len(spans) != 6:
            out[frame] = "not a pose p[x, y, z, rx, ry, rz]"
            continue
        try:
            out[frame] = point_pose(
                "urscript", tuple(float(text[a:b]) for a, b in spans)
            )
        except DataError as exc:
            raise DataError(f"line {_line(text, got[0][1])}: {frame}: {exc}") from None
    return out


def _ur_uses(text: str) -> tuple[list[tuple[str, str, int, int]], dict[str, int]]:
    """The Cartesian targets of move instructions: [(frame, 'p' or variable, index of
    the literal or name, position of the move)], and {variable: position} of variables
    a move uses otherwise (in an expression)."""
    uses: list[tuple[str, str, int, int]] = []
    other: dict[str, int] = {}
    for m in re.finditer(r"\b(movej|movel|movep|movec|servoj)\s*\(", text):
        args = _args(text, m.end() - 1)
        n = 2 if m.group(1) == "movec" else 1
        for a, b in args[:n]:
            got = _ur_target(text, a, b)
            if got is not None:
                uses.append((*got, m.start()))
                continue
            for v in re.finditer(_ID, text[a:b]):
                other.setdefault(v.group(0), a + v.start())
    return uses, other


def _ur_unresolved(
    text: str, uses: list[tuple[str, str, int, int]], assigned: dict
) -> list[CartesianPoint]:
    """Moves whose target is neither a joint list (literal or variable) nor a pose the
    script gives: a call (``pose_add(..)``, ``get_target_tcp_pose()``) or a variable not
    assigned a pose; counted and left, with why."""
    out = []
    for m in re.finditer(r"\b(movej|movel|movep|movec)\s*\(", text):
        args = _args(text, m.end() - 1)
        for a, b in args[: 2 if m.group(1) == "movec" else 1]:
            arg = text[a:b].strip()
            if arg.startswith("["):
                continue  # a joint list
            got = _ur_target(text, a, b)
            if got is not None:
                sites = assigned.get(got[1], [])
                if got[1] == "p" or any(
                    lit >= 0 or re.match(r"\s*\[", text[at:].split("=", 1)[1])
                    for at, lit in sites
                ):
                    continue  # a literal pose, a variable the script sets (or joints)
                why = f"{got[1]}: not assigned a pose p[..] in the script"
            else:
                why = f"a computed target ({arg[:40]})"
            out.append(CartesianPoint(m.group(1), _line(text, a), ((a, a),), (), (),
                                      None, "", "", why_not=why))  # fmt: skip
    return out


def _urscript(text: str) -> list[CartesianPoint]:
    tcps = _ur_tcps(text)

    def tcp_at(pos: int) -> str:
        before = [t for at, t in tcps if at < pos]
        return before[-1] if before else (tcps[0][1] if tcps else "")

    uses, other = _ur_uses(text)
    assigned = _ur_assignments(text)
    features = {u[0] for u in uses if u[0]}
    out = []
    for frame, what, at, pos in uses:  # inline poses
        if what != "p":
            continue
        spans = _bracket_list(text, at)
        if len(spans) != 6:  # p[x, 0.1, ...]: not six numbers
            out.append(CartesianPoint(text[pos:text.find("(", pos)], _line(text, at),
                                      ((at, at),), (), (), None, frame, "",
                                      why_not=_NOT_SIX))  # fmt: skip
        else:
            out.append(_make(text, text[pos:text.find("(", pos)], spans, config=None,
                             frame=frame, tool=tcp_at(pos)))  # fmt: skip
    for name, sites in assigned.items():
        lits = [(a, b) for a, b in sites if b >= 0]
        if not lits or name in features:
            continue
        used = {(u[0], tcp_at(u[3])) for u in uses if u[1] == name}
        polyscope = re.fullmatch(r"\w+_p", name) and re.search(
            rf"^[ \t]*global\s+{name}\s*=", text, re.M
        )
        if not used and not polyscope:
            continue  # a pose no move goes to: not a target
        qm = (
            re.search(rf"\bglobal\s+{name[:-2]}_q\s*=\s*\[", text)
            if polyscope
            else None
        )
        q_spans = _bracket_list(text, qm.end() - 1) if qm else []
        q_vals = tuple(float(text[a:b]) for a, b in q_spans)
        why = ""
        if name in other:
            why = (f"a move uses it in an expression (line {_line(text, other[name])}): "
                   "one correction cannot serve both")  # fmt: skip
        elif len(used) > 1:
            why = "moves use it with different features or TCPs"
        elif len(lits) < len(sites):
            why = "it is also assigned from an expression: its value is not known"
        frame, tool = next(iter(used)) if len(used) == 1 else ("", tcp_at(lits[0][0]))
        for _, b in lits:
            spans = _bracket_list(text, b)
            if len(spans) != 6:  # p[x, 0.1, ...]: not six numbers
                out.append(CartesianPoint(name, _line(text, b), ((b, b),), (), (), None,
                                          frame, tool, why_not=_NOT_SIX))  # fmt: skip
                continue
            out.append(_make(text, name, spans, config=None, frame=frame,
                             tool=tool, q_spans=tuple(q_spans), q_values=q_vals,
                             why_not=why))  # fmt: skip
    out += _ur_unresolved(text, uses, assigned)
    for k, pt in enumerate(out):
        if pt.tool.startswith("?") and not pt.why_not:
            out[k] = replace(pt, why_not=f"set_tcp({pt.tool[1:]}): the TCP is not a pose "
                                         "literal")  # fmt: skip
    return sorted(out, key=lambda c: c.spans[0][0])
