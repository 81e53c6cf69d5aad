"""One Cartesian target of a robot program and the text helpers its readers share
(:mod:`kinecal.io._cartesian_programs`, :mod:`kinecal.io._urscript_targets`)."""

from __future__ import annotations

import re
from dataclasses import dataclass

__all__ = [
    "NUM",
    "CartesianPoint",
    "bracket_list",
    "decimals_of",
    "line_of",
    "make_point",
]

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


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
    why_not : why it cannot be corrected ('' when it can).
    used_at : where the first move to a target defined apart from its moves (a URScript
        pose variable) is, -1 for a target written in its move.
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
    used_at: int = -1  # a variable's first move (where the arm is when it is taught)


def line_of(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def decimals_of(token: str) -> int:
    m = re.match(r"\s*[-+]?\d*\.?(\d*)", token)
    return len(m.group(1)) if m and "." in token else 0


def make_point(text, name, spans, **kw) -> CartesianPoint:
    vals = tuple(float(text[a:b]) for a, b in spans)
    dec = tuple(decimals_of(text[a:b]) for a, b in spans)
    return CartesianPoint(
        name, line_of(text, spans[0][0]), tuple(spans), vals, dec, **kw
    )


def bracket_list(text: str, start: int) -> list[tuple[int, int]]:
    """Spans of the numbers in the '[...]' list opening at ``start``."""
    close = text.find("]", start)
    return [
        (start + 1 + m.start(), start + 1 + m.end())
        for m in re.finditer(NUM, text[start + 1 : close])
    ]
