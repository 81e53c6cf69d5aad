"""Shared parts of the Cartesian program readers (:mod:`._cartesian_programs`): the target
record, spans of numbers, bracket matching, a target's numbers as a pose, and the offsets
a move takes its target at (RAPID ``Offs``/``RelTool``, FANUC ``Offset``/``Tool_Offset``)."""

from __future__ import annotations

import functools
import re
from dataclasses import dataclass, replace

import numpy as np

from kinecal.errors import DataError
from kinecal.geometry import (
    euler_zyx_to_matrix,
    make_transform,
    quat_wxyz_to_matrix,
    so3_exp,
)
from kinecal.typing import Pose

__all__ = [
    "CartesianPoint",
    "apply_offset",
    "check_pose_numbers",
    "code_only",
    "point_pose",
    "remove_offset",
]

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class CartesianPoint:
    """One Cartesian target.

    Attributes
    ----------
    name, line : how the program names it, 1-based line of its first value.
    spans : character spans of its pose numbers (FANUC: with the blanks before).
    values : the numbers as written (x, y, z then W P R / A B C / q1..q4 / rx ry rz).
    decimals : decimals of each number as written.
    config : the configuration as written: FANUC ``('N', 'U', 'T', t1, t4, t6)``, KRL
        ``(S, T)``, RAPID ``(cf1, cf4, cf6, cfx)``; None where the target has none.
    frame, tool : the user / tool frame it names (FANUC UF/UT numbers, KRL BASE_NO /
        TOOL_NO, RAPID wobj / tool names, URScript the TCP pose text or '').
    q_spans : URScript Polyscope ``Name_q`` joints (spans), else empty.
    config_spans : where the configuration is written (FANUC: the CONFIG text inside the
        quotes; KRL: S, T; RAPID: cf1, cf4, cf6, cfx).
    q_values : those joints [rad].
    register : FANUC: 'cartesian' or 'joint' for a position register whose value was
        given (its span: where the first move names it; the value is written to a
        register program, not the text), else ''.
    why_not : why it cannot be corrected ('' when it can).
    offset : the offset (see :func:`apply_offset`) the target is corrected at (the pose
        the robot goes to is ``apply_offset(values, offset)``): RAPID ``Offs``/``RelTool``,
        FANUC ``Offset,PR[k]``/``Tool_Offset,PR[k]``.
    follows : for a move with an offset (RAPID ``Offs(p10, ..)``, FANUC ``L P[4] ..
        Offset,PR[5]``) that is not the one the target is corrected for, the target's
        name (no text of its own: it follows that correction).
    """

    name: str
    line: int
    spans: tuple[tuple[int, int], ...]
    values: tuple[float, ...]
    decimals: tuple[int, ...]
    config: tuple | None
    frame: str
    tool: str
    q_spans: tuple[tuple[int, int], ...] = ()
    q_values: tuple[float, ...] = ()
    why_not: str = ""
    config_spans: tuple[tuple[int, int], ...] = ()
    register: str = ""
    offset: tuple = ()
    follows: str = ""


_COMMENT = {"rapid": "!", "krl": ";", "urscript": "#"}


def code_only(text: str, fmt: str) -> str:
    """``text`` with its comments blanked (each character a space, the line ends kept,
    so positions stay those of ``text``): RAPID ``!``, KRL ``;`` (``;FOLD`` lines too),
    URScript ``#`` to the end of the line outside strings; FANUC ``!comment`` and
    ``//``-commented instruction lines. A target written in a comment is no target."""
    if fmt == "fanuc-ls":
        head = re.search(r"^/POS\b", text, re.M)
        stop = head.start() if head else len(text)
        blank = re.compile(r"^([ \t]*\d*[ \t]*:[ \t]*)((?:!|//)[^\r\n]*)", re.M)
        return blank.sub(lambda m: m.group(1) + " " * len(m.group(2)),
                         text[:stop]) + text[stop:]  # fmt: skip
    mark = _COMMENT.get(fmt)
    if mark is None or mark not in text:
        return text
    lines = text.split("\n")
    for k, line in enumerate(lines):
        if mark not in line:
            continue
        quoted = False
        for i, ch in enumerate(line):
            quoted ^= ch == '"'
            if ch == mark and not quoted:
                lines[k] = line[:i] + re.sub(r"[^\r]", " ", line[i:])
                break
    return "\n".join(lines)


@functools.lru_cache(maxsize=4)
def _newlines(text: str) -> np.ndarray:
    """Offsets of the line ends of ``text`` (a program's: looked up per target)."""
    return np.array([m.start() for m in re.finditer("\n", text)], dtype=np.int64)


def _line(text: str, pos: int) -> int:
    """The 1-based line of offset ``pos`` in ``text``: a search in the line ends,
    counted once per text (counting them per target took 16 s for a program of 20 000
    moves)."""
    return int(np.searchsorted(_newlines(text), pos)) + 1


def _decimals(token: str) -> int:
    m = re.match(r"\s*[-+]?\d*\.?(\d*)", token)
    return len(m.group(1)) if m and "." in token else 0


def _make(text, name, spans, **kw) -> CartesianPoint:
    vals = tuple(float(text[a:b]) for a, b in spans)
    dec = tuple(_decimals(text[a:b]) for a, b in spans)
    return CartesianPoint(name, _line(text, spans[0][0]), tuple(spans), vals, dec, **kw)


def _bracket_list(text: str, start: int) -> list[tuple[int, int]]:
    """Spans of the numbers in the '[...]' list opening at ``start``."""
    close = text.find("]", start)
    return [
        (start + 1 + m.start(), start + 1 + m.end())
        for m in re.finditer(_NUM, text[start + 1 : close])
    ]


def _close(text: str, at: int) -> int:
    """The index just past the bracket closing the one at ``at`` (end of text if
    none)."""
    depth = 0
    for i in range(at, len(text)):
        depth += text[i] in "(["
        depth -= text[i] in ")]"
        if depth == 0:
            return i + 1
    return len(text)


def _strip(text: str, a: int, b: int) -> tuple[int, int]:
    while a < b and text[a].isspace():
        a += 1
    while b > a and text[b - 1].isspace():
        b -= 1
    return a, b


def _args(text: str, open_at: int) -> list[tuple[int, int]]:
    """Spans of the top-level arguments of the call whose '(' is at ``open_at``."""
    end = _close(text, open_at) - 1
    out, depth, start = [], 0, open_at + 1
    for i in range(open_at + 1, end):
        c = text[i]
        depth += c in "(["
        depth -= c in ")]"
        if c == "," and depth == 0:
            out.append(_strip(text, start, i))
            start = i + 1
    out.append(_strip(text, start, end))
    return out


# What each format's pose numbers are, for a message.
_POSE_WORDS = {
    "urscript": "x, y, z [m] and a rotation vector rx, ry, rz [rad]",
    "rapid": "x, y, z [mm] and a unit quaternion q1..q4",
    "fanuc-ls": "X, Y, Z [mm] and W, P, R [deg]",
    "krl": "X, Y, Z [mm] and A, B, C [deg]",
}


def check_pose_numbers(fmt: str, values: tuple[float, ...] | np.ndarray) -> None:
    """Refuse numbers that are no pose of ``fmt``: not finite, a position beyond 1 km,
    a rotation vector over 100 rad or angles over 1e5 deg, a quaternion far from unit
    length (a damaged or hand-edited value; 1e308 overflowed in the rotation)."""
    v = np.asarray(values, np.float64)
    ok = v.size >= 6 and bool(np.isfinite(v).all())
    if ok:
        ok = float(np.abs(v[:3]).max()) <= (1e3 if fmt == "urscript" else 1e6)
        if fmt == "urscript":
            ok = ok and float(np.linalg.norm(v[3:6])) <= 100.0
        elif fmt == "rapid":
            ok = ok and v.size >= 7 and 0.5 <= float(np.linalg.norm(v[3:7])) <= 2.0
        else:
            ok = ok and float(np.abs(v[3:6]).max()) <= 1e5
    if not ok:
        shown = ", ".join(f"{x:.6g}" for x in v)
        raise DataError(f"[{shown}] is no pose; expected {_POSE_WORDS[fmt]}.")


def point_pose(fmt: str, values: tuple[float, ...]) -> Pose:
    """A target's numbers as a pose (4, 4) in SI [m] (DataError: :func:`check_pose_numbers`)."""
    v = np.asarray(values, np.float64)
    check_pose_numbers(fmt, v)
    if fmt == "urscript":
        return make_transform(so3_exp(v[3:6]), v[:3])
    if fmt == "rapid":
        return make_transform(quat_wxyz_to_matrix(v[3:7]), v[:3] * 1e-3)
    a = np.radians(v[3:6])
    # FANUC W, P, R about x, y, z; KRL A, B, C about z, y, x.
    R = euler_zyx_to_matrix(a[::-1] if fmt == "fanuc-ls" else a)
    return make_transform(R, v[:3] * 1e-3)


def _offset_matrix(offset: tuple) -> tuple[Pose, bool]:
    """(M, left): the offset as a pose M [m], multiplied from the left (a displacement in
    the user / object frame) or from the right (in the tool frame) of the target."""
    kind, v = offset[0], np.asarray(offset[1:], np.float64)
    if kind == "Offs":
        return make_transform(np.eye(3), v[:3] * 1e-3), True
    if kind == "RelTool":
        # ABB: "first around the x-axis, then around the new y-axis and then around the
        # new z-axis" of the tool: Rx · Ry · Rz, after the displacement in the tool frame.
        rx, ry, rz = np.radians(v[3:6])
        R = _rot("x", rx) @ _rot("y", ry) @ _rot("z", rz)
        return make_transform(R, v[:3] * 1e-3), False
    # FANUC: the register's X, Y, Z, W, P, R as a pose: Offset in the user frame (T' = M ·
    # T), Tool_Offset in the tool frame (T' = T · M).
    return point_pose("fanuc-ls", tuple(v[:6])), kind == "Offset"


def _rot(axis: str, a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    i, j = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    R = np.eye(3)
    R[i, i], R[i, j], R[j, i], R[j, j] = c, -s, s, c
    return R


def apply_offset(T: Pose, offset: tuple) -> Pose:
    """The pose a move with ``offset`` goes to for the target ``T`` (4, 4) [m]: RAPID
    ``('Offs', dx, dy, dz)`` (displacement in the object frame), ``('RelTool', dx, dy,
    dz, rx, ry, rz)`` (displacement, then rotations about x, the new y, the new z, in the
    tool frame) [mm, deg]; FANUC ``('Offset', x, y, z, w, p, r)`` (the register's pose
    applied in the user frame), ``('Tool_Offset', ..)`` (in the tool frame); () none."""
    if not offset:
        return T
    if not np.isfinite(np.asarray(offset[1:], np.float64)).all():
        raise DataError(f"the offset {offset[0]}{tuple(offset[1:])} is not finite.")
    M, left = _offset_matrix(offset)
    return M @ T if left else T @ M


def remove_offset(T: Pose, offset: tuple) -> Pose:
    """The target whose ``offset`` pose is ``T`` (the inverse of :func:`apply_offset`)."""
    if not offset:
        return T
    if not np.isfinite(np.asarray(offset[1:], np.float64)).all():
        raise DataError(f"the offset {offset[0]}{tuple(offset[1:])} is not finite.")
    M, left = _offset_matrix(offset)
    return np.linalg.inv(M) @ T if left else T @ np.linalg.inv(M)


Use = tuple  # (offset | None | ('?', why), position of the move, its name)


def offset_targets(
    text: str, pt: CartesianPoint, uses: list[Use]
) -> list[CartesianPoint]:
    """``pt`` and the moves that take it with an offset, each counted.

    ``uses``: (offset, position of the move, its name) per move to ``pt``: offset None for
    the target itself, a tuple (:func:`apply_offset`), or ``('?', why)`` for one whose
    value is not known. ``pt`` is corrected for itself where a move goes to it, else for
    its first known offset (a ``pt`` left stands for that move); every other known offset
    follows that correction (checked, counted); an unknown one is left with its reason
    (``pt`` itself too when it has no other use)."""
    direct = not uses or any(u[0] is None for u in uses)
    known = [u for u in uses if u[0] is not None and u[0][0] != "?"]
    unknown = [u for u in uses if u[0] is not None and u[0][0] == "?"]
    own = known[0] if known and not direct else None
    first = unknown[0] if unknown and not direct and not known else None
    why = pt.why_not or (first[0][1] if first else "")
    out = [replace(pt, offset=own[0] if own else (), why_not=why)]
    for u in uses:
        if u[0] is None or u is own or u is first:
            continue
        bad = u[0][0] == "?"
        out.append(replace(pt, name=u[2], line=_line(text, u[1]), spans=((u[1], u[1]),),
                           config_spans=(), offset=() if bad else u[0], follows=pt.name,
                           why_not=u[0][1] if bad else pt.why_not))  # fmt: skip
    return out
