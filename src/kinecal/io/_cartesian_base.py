"""Shared parts of the Cartesian program readers (:mod:`._cartesian_programs`): the target
record, spans of numbers, bracket matching, and a target's numbers as a pose."""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from kinecal.geometry import (
    euler_zyx_to_matrix,
    make_transform,
    quat_wxyz_to_matrix,
    so3_exp,
)
from kinecal.typing import Pose

__all__ = ["CartesianPoint", "point_pose"]

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
    offset : RAPID: the ``Offs``/``RelTool`` offset (see :func:`apply_offset`) the
        target is taken at (the robtarget's pose is ``apply_offset(values, offset)``).
    follows : RAPID: for a move to ``Offs(p10, ..)`` that is not the one ``p10`` is
        corrected for, 'p10' (no text of its own: it follows p10's correction).
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


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


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


def point_pose(fmt: str, values: tuple[float, ...]) -> Pose:
    """A target's numbers as a pose (4, 4) in SI [m]."""
    v = np.asarray(values, np.float64)
    if fmt == "urscript":
        return make_transform(so3_exp(v[3:6]), v[:3])
    if fmt == "rapid":
        return make_transform(quat_wxyz_to_matrix(v[3:7]), v[:3] * 1e-3)
    a = np.radians(v[3:6])
    # FANUC W, P, R about x, y, z; KRL A, B, C about z, y, x.
    R = euler_zyx_to_matrix(a[::-1] if fmt == "fanuc-ls" else a)
    return make_transform(R, v[:3] * 1e-3)
