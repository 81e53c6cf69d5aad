"""The Cartesian targets of a URScript program (issue 34), every move counted.

Each ``movej``, ``movel``, ``movep`` (and both poses of ``movec``) is classified by its
target argument:

* ``[..]``, a joint list: a joint target (:mod:`kinecal.io._programs`), not here;
* ``p[x, y, z, rx, ry, rz]``: a pose in the base frame, corrected in place;
* a pose variable (``name = p[..]``, ``global``/``local`` or not, assigned once): the
  target is its assignment, corrected there once however many moves use it; Polyscope's
  ``global Waypoint_1_p=p[..]`` keeps its ``Waypoint_1_q`` joints beside it;
* ``pose_trans(FEATURE, POSE)``: ``POSE`` (a literal or a pose variable) in the frame of
  ``FEATURE`` (a literal or a pose variable: a Polyscope feature such as ``Plane_1``);
* ``get_inverse_kin(POSE, ..)`` (Polyscope's MoveJ to a waypoint): ``POSE`` as above;
* anything else (an expression, ``get_inverse_kin(..)``, a variable assigned twice or
  computed): counted and left as written, with the reason.

The tool is the last ``set_tcp(..)`` before the move (a literal or a pose variable; the
first one for moves before any; the flange without one). A pose variable used in
different frames or with different tools is left.
"""

from __future__ import annotations

import re

from kinecal.io._cartesian_point import (
    CartesianPoint,
    bracket_list,
    line_of,
    make_point,
)

__all__ = ["urscript_targets"]

_MOVES = r"\b(movej|movel|movep|movec)\s*\("
_POSE_VAR = r"^[ \t]*(?:(?:global|local)\s+)?([A-Za-z_]\w*)\s*=\s*p\["


def _args(text: str, open_at: int) -> list[tuple[int, int]]:
    """Spans of the top-level arguments of the call whose '(' is at ``open_at``."""
    depth, start, out = 0, open_at + 1, []
    for i in range(open_at, len(text)):
        c = text[i]
        if c in "([":
            depth += 1
        elif c in ")]":
            depth -= 1
            if depth == 0:
                out.append((start, i))
                return out
        elif c == "," and depth == 1:
            out.append((start, i))
            start = i + 1
    out.append((start, len(text)))
    return out


def _pose_vars(text: str) -> dict[str, list[int]]:
    """Pose variables: name -> where each assignment's ``p[`` is (-1: assigned from an
    expression too)."""
    out: dict[str, list[int]] = {}
    for m in re.finditer(_POSE_VAR, text, re.M):
        out.setdefault(m.group(1), []).append(m.end() - 2)  # at its 'p[
    for m in re.finditer(r"^[ \t]*(?:(?:global|local)\s+)?([A-Za-z_]\w*)\s*=(?!=)", text,
                         re.M):  # fmt: skip
        rest = text[m.end() : m.end() + 80].lstrip()
        if m.group(1) in out and not rest.startswith("p["):
            out[m.group(1)].append(-1)  # also assigned from an expression
    return out


def _joint_var(text: str, name: str) -> bool:
    """Whether ``name`` is assigned a joint list ``[..]`` (once) in the script."""
    if not re.fullmatch(r"[A-Za-z_]\w*", name):
        return False
    pat = rf"^[ \t]*(?:(?:global|local)\s+)?{name}\s*=\s*\["
    return len(re.findall(pat, text, re.M)) == 1


class _Reader:
    def __init__(self, text: str) -> None:
        self.text = text
        self.vars = _pose_vars(text)
        self.tcps = [
            (m.start(), a)
            for m in re.finditer(r"\bset_tcp\s*\(", text)
            for a in [_args(text, m.end() - 1)[0]]
        ]

    def pose(self, a: int, b: int) -> tuple[list[tuple[int, int]] | None, str, str]:
        """An argument as a pose: (number spans, its text p[..], why not)."""
        arg = self.text[a:b].strip()
        at = a + self.text[a:b].find(arg[:1]) if arg else a
        if arg.startswith("p["):
            spans = bracket_list(self.text, at + 1)
            if len(spans) == 6:
                return spans, self.text[at : self.text.find("]", at) + 1], ""
            return None, "", f"{arg[:40]}: expected p[x, y, z, rx, ry, rz]"
        if re.fullmatch(r"[A-Za-z_]\w*", arg):
            where = self.vars.get(arg)
            if where is None:
                return None, "", f"{arg}: not assigned a pose p[..] in the script"
            if len(where) > 1:
                return None, "", f"{arg}: assigned more than once"
            return self.pose(where[0], self.text.find("]", where[0]) + 1)
        return None, "", f"a computed target ({arg[:40]})"

    def tool(self, pos: int) -> tuple[str, str]:
        """The TCP pose text at ``pos`` and why it is unknown ('' when known)."""
        before = [t for t in self.tcps if t[0] < pos] or self.tcps[:1]
        if not before:
            return "", ""
        spans, lit, why = self.pose(*before[-1][1])
        return (lit, "") if spans else ("", f"set_tcp: {why}")


def urscript_targets(text: str) -> list[CartesianPoint]:
    """The Cartesian targets of a URScript text, every move counted (module docstring)."""
    rd = _Reader(text)
    found: dict[int, tuple[str, list, str, str, str, int, int]] = {}  # by 1st number
    left = []
    for m in re.finditer(_MOVES, text):
        args = _args(text, m.end() - 1)
        targets = args[:2] if m.group(1) == "movec" else args[:1]
        for a, b in targets:
            arg = text[a:b].strip()
            if re.fullmatch(r"get_inverse_kin\s*\((.*)\)", arg, re.S):
                # Polyscope's MoveJ to a pose: movej(get_inverse_kin(POSE, qnear=..))
                a, b = _args(text, a + text[a:b].find("("))[0]
                arg = text[a:b].strip()
            if arg.startswith("[") or _joint_var(text, arg):
                continue  # a joint target (kinecal.io._programs)
            frame, why = "", ""
            call = re.fullmatch(r"pose_trans\s*\((.*)\)", arg, re.S)
            if call is not None:
                inner = a + text[a:b].find("(")
                parts = _args(text, inner)
                if len(parts) != 2:
                    spans, why = None, f"{arg[:40]}: expected pose_trans(FEATURE, POSE)"
                else:
                    fs, frame, fwhy = rd.pose(*parts[0])
                    spans, _, why = rd.pose(*parts[1])
                    why = f"feature {fwhy}" if fs is None else why
            else:
                spans, _, why = rd.pose(a, b)
            tool, twhy = rd.tool(m.start())
            why = why or twhy
            if spans is None or why:
                left.append((m.group(1), a, why))
                continue
            key = spans[0][0]
            prev = found.get(key)
            if prev is not None and (prev[3], prev[4]) != (frame, tool):
                found[key] = (*prev[:5], -1, prev[6])  # in different frames or tools
                continue
            found.setdefault(key, (m.group(1), spans, "", frame, tool, 0, m.start()))
    out = [CartesianPoint(name, line_of(text, at), ((at, at),), (), (), None, "", "",
                          why_not=why)
           for name, at, why in left]  # fmt: skip
    for key, (name, spans, _, frame, tool, bad, first) in found.items():
        var = re.search(r"(\w+)\s*=\s*p\[\s*$", text[max(0, key - 200) : key])
        label = var.group(1) if var else name
        q_spans: list[tuple[int, int]] = []
        if var and label.endswith("_p"):
            qm = re.search(rf"\bglobal\s+{label[:-2]}_q\s*=\s*\[", text)
            q_spans = bracket_list(text, qm.end() - 1) if qm else []
        why = "used in different frames or with different tools" if bad else ""
        out.append(
            make_point(text, label, spans, config=None, frame=frame, tool=tool,
                       q_spans=tuple(q_spans),
                       q_values=tuple(float(text[a:b]) for a, b in q_spans),
                       why_not=why, used_at=first if first > key else -1)
        )  # fmt: skip
    return sorted(out, key=lambda c: c.spans[0][0])
