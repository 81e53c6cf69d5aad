"""Joint targets in robot programs: read them, write corrected values back in place.

Only the numbers of joint targets are touched; every other byte of the program is kept
(line ends, comments, Cartesian targets, speeds). Supported (one text format per vendor
family, joint targets only):

==========  =========================  ==========================================  =====
format      files                      joint target                                unit
==========  =========================  ==========================================  =====
fanuc-ls    FANUC TP ASCII ``.ls``     ``/POS`` records ``P[n]{ GP1: ... J1= x``   deg
                                       ``deg, ... }`` (joint representation; the
                                       first motion group)
urscript    URScript ``.script``       ``movej([q1, ..., q6], ...)`` and the same  rad
                                       first argument of ``movel``, ``movep``,
                                       ``servoj``
rapid       ABB RAPID ``.mod/.modx/``  ``jointtarget name := [[j1, ..., j6],``     deg
            ``.prg``                   ``[eax]]`` and ``MoveAbsJ [[...], [...]]``
krl         KUKA KRL ``.src/.dat``     ``{A1 x, A2 x, ...}`` aggregates (AXIS,     deg
                                       E6AXIS), external axes E1.. kept
==========  =========================  ==========================================  =====

Prismatic joints are in mm in every format but URScript (metres). Cartesian targets
(FANUC ``X = .. mm``, URScript ``p[...]``, RAPID ``robtarget``, KRL ``{X .., A ..}``
frames) are read by :mod:`kinecal.io._cartesian_programs`; here they are only counted
(``Program.skipped``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinecal.errors import DataError
from kinecal.io._cartesian_base import _line, code_only
from kinecal.io._program_checks import (
    check_degrees,
    check_fanuc_units,
    check_positions,
    check_values,
)
from kinecal.robot import RobotDescription
from kinecal.robot._robot_file import read_bounded
from kinecal.typing import Float

__all__ = [
    "PROGRAM_FORMATS",
    "Program",
    "ProgramPoint",
    "detect_program_format",
    "program_bytes",
    "program_joints",
    "read_program",
    "write_program",
    "written_joints",
]

PROGRAM_FORMATS = ("fanuc-ls", "urscript", "rapid", "krl")
_EXTENSIONS = {
    ".ls": "fanuc-ls",
    ".script": "urscript",
    ".urscript": "urscript",
    ".mod": "rapid",
    ".modx": "rapid",
    ".prg": "rapid",
    ".src": "krl",
    ".dat": "krl",
}
_UNIT = {"fanuc-ls": "deg", "urscript": "rad", "rapid": "deg", "krl": "deg"}
_MIN_DECIMALS = {"fanuc-ls": 3, "urscript": 8, "rapid": 4, "krl": 4}
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class ProgramPoint:
    """One joint target of a program.

    Attributes
    ----------
    name : how the program names it ('P[3]', 'jpos10', 'movej', 'XP1', ...).
    line : 1-based line of its first joint value.
    spans : (start, end) character spans of the joint values j1..jN in the text; for
        FANUC the span holds the blanks before the number (its column width).
    values : the values as written [deg or rad; mm or m].
    decimals : decimals of each value as written.
    why_not : why it is not corrected ('' when it is): a FANUC P[] an incremental move
        (INC) uses holds a displacement, not joints to reach.
    """

    name: str
    line: int
    spans: tuple[tuple[int, int], ...]
    values: tuple[float, ...]
    decimals: tuple[int, ...]
    why_not: str = ""


@dataclass(frozen=True)
class Program:
    """A program's text and its joint targets.

    Attributes
    ----------
    path, format : where it came from, one of :data:`PROGRAM_FORMATS`.
    text : the whole program (decoded so that it encodes back to the same bytes).
    points : joint targets in the order of the text.
    skipped : Cartesian targets found and left as they are.
    """

    path: str
    format: str
    text: str
    points: tuple[ProgramPoint, ...]
    skipped: int


def detect_program_format(path: str | Path) -> str | None:
    """The program format of a file by its extension, or None (a CSV of targets)."""
    return _EXTENSIONS.get(Path(path).suffix.lower())


def _decimals(token: str) -> int:
    m = re.match(r"[-+]?\d*\.?(\d*)", token.strip())
    return len(m.group(1)) if m and "." in token else 0


def _point(text: str, name: str, spans: list[tuple[int, int]]) -> ProgramPoint:
    vals = []
    for a, b in spans:
        try:
            vals.append(float(text[a:b]))
        except ValueError:  # pragma: no cover - the patterns only match numbers
            raise DataError(
                f"line {_line(text, a)}: not a number {text[a:b]!r}."
            ) from None
    return ProgramPoint(
        name,
        _line(text, spans[0][0]),
        tuple(spans),
        tuple(vals),
        tuple(_decimals(text[a:b]) for a, b in spans),
    )


def _fanuc(text: str) -> tuple[list[ProgramPoint], int]:
    pos = re.search(r"^/POS\b", text, re.M)
    if pos is None:
        return [], 0
    end = re.search(r"^/END\b", text[pos.end() :], re.M)
    stop = pos.end() + end.start() if end else len(text)
    points, skipped = [], 0
    incremental = _incremental(text[: pos.start()])
    for rec in re.finditer(r"(P\[[^\]]*\])\s*\{(.*?)\};", text[pos.end() : stop], re.S):
        body_at = pos.end() + rec.start(2)
        body = rec.group(2)
        inner = re.search(r"P\[[^\]]*\]\s*\{", body)
        if inner is not None:  # an unclosed record would lend its name to the next
            raise DataError(
                f"line {_line(text, pos.end() + rec.start(1))}: {rec.group(1)} is not "
                f"closed by '}};' before the next position on line "
                f"{_line(text, body_at + inner.start())}; expected each position as "
                "P[n]{ ... };"
            )
        g1 = re.search(r"GP1\s*:(.*?)(?=GP\d+\s*:|\Z)", body, re.S)
        if g1 is None:
            continue
        seg, seg_at = g1.group(1), body_at + g1.start(1)
        joints = list(re.finditer(rf"\bJ(\d+)\s*=(\s*{_NUM})\s*(?:deg|mm)", seg))
        if not joints:
            skipped += 1
            continue
        order = [int(m.group(1)) for m in joints]
        if order != list(range(1, len(order) + 1)):
            raise DataError(
                f"line {_line(text, seg_at)}: {rec.group(1)} lists joints {order}; "
                "expected J1, J2, ... in order."
            )
        spans = [(seg_at + m.start(2), seg_at + m.end(2)) for m in joints]
        pt = _point(text, rec.group(1), spans)
        if _index(rec.group(1)) in incremental:
            pt = replace(pt, why_not=_INC)
        points.append(pt)
    return points, skipped


_INC = "an incremental move (INC) uses it: its joints are a displacement, not a pose"


def _index(name: str) -> int | None:
    """n of ``P[n]`` / ``P[n:comment]``."""
    m = re.match(r"P\[\s*(\d+)", name)
    return int(m.group(1)) if m else None


def _incremental(text: str) -> set[int]:
    """The P[n] that incremental motions (``J P[2] 100% FINE INC``) move by."""
    moves = re.finditer(
        r"^\s*\d+\s*:\s*[JLCA]\s+P\[\s*(\d+)[^\]]*\]([^;]*);", text, re.M
    )
    return {
        int(m.group(1)) for m in moves if re.search(r"(?<!\w)INC\b", m.group(2), re.I)
    }


def _bracket_numbers(text: str, start: int) -> list[tuple[int, int]] | None:
    """Spans of the numbers of the bracket list opening at ``start`` ('['), or None
    when the list holds anything but numbers."""
    close = text.find("]", start)
    if close < 0:
        return None
    body = text[start + 1 : close]
    spans = []
    for part in re.finditer(r"[^,]+", body):
        tok = part.group(0)
        m = re.fullmatch(rf"\s*({_NUM})\s*", tok)
        if m is None:
            return None
        spans.append(
            (start + 1 + part.start() + m.start(1), start + 1 + part.start() + m.end(1))
        )
    return spans


def _urscript(text: str) -> tuple[list[ProgramPoint], int]:
    points, skipped = [], 0
    for m in re.finditer(r"\b(movej|movel|movep|servoj)\s*\(\s*(p?)\[", text):
        if m.group(2):  # a pose p[x, y, z, rx, ry, rz]
            skipped += 1
            continue
        spans = _bracket_numbers(text, m.end() - 1)
        if spans:
            points.append(_point(text, m.group(1), spans))
    # Moves to a joint-list variable assigned once (q_home = [..]): its assignment.
    moves = r"\b(?:movej|movel|movep|servoj)\s*\(\s*([A-Za-z_]\w*)\s*[,)]"
    scope = r"^[ \t]*(?:(?:global|local)\s+)?"
    assigned = {
        name: list(re.finditer(rf"{scope}{name}\s*=(?!=)", text, re.M))
        for name in set(re.findall(moves, text))
    }
    for name, found in sorted(assigned.items()):
        if len(found) != 1:
            continue
        at = text.find("[", found[0].end())
        if text[found[0].end() : at].strip():  # not a list literal (p[..], a call)
            continue
        spans = _bracket_numbers(text, at)
        if spans:
            points.append(_point(text, name, spans))
    points.sort(key=lambda pt: pt.spans[0][0])
    return points, skipped


def _rapid(text: str) -> tuple[list[ProgramPoint], int]:
    points = []
    pat = r"\bjointtarget\s+(\w+)\s*:=\s*\[\s*\[|\b(MoveAbsJ)\s*\[\s*\["
    for m in re.finditer(pat, text, re.I):
        spans = _bracket_numbers(text, m.end() - 1)
        if spans:
            points.append(_point(text, m.group(1) or m.group(2), spans))
    skipped = len(re.findall(r"\brobtarget\s+\w+\s*:=", text, re.I))
    return points, skipped


def _krl(text: str) -> tuple[list[ProgramPoint], int]:
    points, skipped = [], 0
    for m in re.finditer(r"\{([^{}]*)\}", text):
        body = m.group(1)
        if re.search(r"\bX\s+" + _NUM, body):  # a Cartesian FRAME/POS/E6POS
            skipped += 1
            continue
        axes = list(re.finditer(rf"\bA(\d)\s+({_NUM})", body))
        if not axes:
            continue
        order = [int(a.group(1)) for a in axes]
        head = text[text.rfind("\n", 0, m.start()) + 1 : m.start()]
        if order != list(range(1, len(order) + 1)) or len(order) < 6 or re.search(
            r"_REL\s*$", head, re.I
        ):  # fmt: skip
            continue  # relative or partial: counted and left by the Cartesian reader
        decl = re.search(r"(\w+)\s*=\s*$", text[max(0, m.start() - 80) : m.start()])
        name = decl.group(1) if decl else "AXIS"
        at = m.start(1)
        points.append(
            _point(text, name, [(at + a.start(2), at + a.end(2)) for a in axes])
        )
    return points, skipped


def _unread(code: str, fmt: str) -> list[tuple[int, str]]:
    """Joint targets the readers pass over (line, what): a URScript or RAPID joint list
    holding expressions (``movej([d2r(10), ...])``, ``[[10+5, ...]]``), a URScript move
    to a joint-list variable assigned more than once. They were written back
    uncorrected without a word (the run said every target was compensated)."""
    out = []
    if fmt in ("urscript", "rapid"):
        pat = (
            r"\b(movej|movel|movep|servoj)\s*\(\s*\["
            if fmt == "urscript"
            else r"\bjointtarget\s+(\w+)\s*:=\s*\[\s*\[|\b(MoveAbsJ)\s*\[\s*\["
        )
        for m in re.finditer(pat, code, re.I):
            if _bracket_numbers(code, m.end() - 1) is None:
                close = code.find("]", m.end())
                body = code[m.end() : close if close >= 0 else m.end() + 40].strip()
                name = next(g for g in m.groups() if g)
                out.append((_line(code, m.start()), f"{name} [{body[:40]}]"))
    if fmt == "rapid":  # MoveAbsJ to a jointtarget this module does not define
        known = {n.lower() for n in re.findall(r"\bjointtarget\s+(\w+)", code, re.I)}
        for m in re.finditer(r"\bMoveAbsJ\s+([A-Za-z_]\w*)\b", code, re.I):
            if m.group(1).lower() not in known:
                out.append((_line(code, m.start()), f"MoveAbsJ {m.group(1)}, not "
                            "defined in this module"))  # fmt: skip
    if fmt == "urscript":
        moves = r"\b(?:movej|movel|movep|servoj)\s*\(\s*([A-Za-z_]\w*)\s*[,)]"
        for name in sorted(set(re.findall(moves, code))):
            scope = rf"^[ \t]*(?:(?:global|local)\s+)?{name}\s*="
            every = list(re.finditer(rf"{scope}(?!=)", code, re.M))
            lists = [a for a in every if re.match(r"\s*\[", code[a.end() :])]
            if lists and len(every) > 1:
                out.append((_line(code, every[0].start()), f"{name}, assigned "
                            f"{len(every)} times"))  # fmt: skip
            elif lists:  # assigned once, a list: of numbers?
                at = code.find("[", lists[0].end())
                if _bracket_numbers(code, at) is None:
                    body = code[at + 1 : code.find("]", at)].strip()
                    out.append((_line(code, at), f"{name} [{body[:40]}]"))
    return sorted(out)


# The largest program read [bytes]: 200 000 URScript moves are 10 MB (read in 11 s);
# beyond, a device or a wrong file (/dev/zero filled the memory).
MAX_PROGRAM_BYTES = 64 << 20
_PAIRS = {"(": ")", "[": "]", "{": "}"}
# A program's closing line per opening one (format: [(opening, closing, what)]).
_ENDS = {
    "fanuc-ls": [(r"^/PROG\b", r"^/END\b", "/END")],
    "krl": [
        (r"^[ \t]*(?:GLOBAL[ \t]+)?DEFDAT\b", r"^[ \t]*ENDDAT\b", "ENDDAT"),
        (r"^[ \t]*(?:GLOBAL[ \t]+)?DEF(?:FCT)?\b", r"^[ \t]*END(?:FCT)?[ \t]*$", "END"),
    ],
    "rapid": [(r"^[ \t]*MODULE\b", r"^[ \t]*ENDMODULE\b", "ENDMODULE")],
}


def check_complete(code: str, fmt: str) -> None:
    """Refuse a truncated or damaged program: a bracket ``( [ {`` left open or closed
    without an opening one (outside strings), or a program without its closing line
    (FANUC ``/END``, KRL ``ENDDAT`` / ``END``, RAPID ``ENDMODULE``). A target cut in
    the middle was skipped silently (and the rest of the file read as if whole)."""
    stack: list[int] = []
    quote = ""  # inside a string (to the line's end at most)
    for i, ch in enumerate(code):
        if quote:
            if ch == quote or ch == "\n":
                quote = ""
        elif ch == '"' or (ch == "'" and fmt == "urscript"):
            quote = ch
        elif ch in _PAIRS:
            stack.append(i)
        elif ch in ")]}":
            if not stack or _PAIRS[code[stack[-1]]] != ch:
                raise DataError(
                    f"line {_line(code, i)}: {ch!r} closes no {_opener(ch)!r}; expected "
                    "a complete program (a truncated or damaged copy?)."
                )
            stack.pop()
    if stack:
        i = stack[-1]
        raise DataError(
            f"line {_line(code, i)}: {code[i]!r} is not closed; expected a complete "
            "program (a truncated or damaged copy?)."
        )
    for head, tail, what in _ENDS.get(fmt, []):
        if re.search(head, code, re.M | re.I) and not re.search(
            tail, code, re.M | re.I
        ):
            raise DataError(
                f"line {code.count(chr(10)) + 1}: the file ends without {what}; expected "
                "a complete program (a truncated copy?)."
            )


def _opener(ch: str) -> str:
    return next(k for k, v in _PAIRS.items() if v == ch)


_READERS = {"fanuc-ls": _fanuc, "urscript": _urscript, "rapid": _rapid, "krl": _krl}


def read_program(path: str | Path, fmt: str | None = None) -> Program:
    """Read a program's joint targets (see the module docstring for the formats).

    Raises
    ------
    DataError
        Unknown format, unreadable file, a malformed joint target, no joint target.
    """
    from kinecal._outputs import note_input

    note_input(path)
    p = Path(path)
    fmt = fmt or detect_program_format(p)
    if fmt not in _READERS:
        raise DataError(
            f"{p}: unknown program format {fmt!r}; expected one of {', '.join(PROGRAM_FORMATS)}."
        )
    try:
        # Bytes that are not UTF-8 (Shift-JIS comments, Latin-1) survive as surrogates.
        raw = read_bounded(p, MAX_PROGRAM_BYTES, f"a {fmt} program")
    except OSError as exc:
        raise DataError(f"{p}: cannot read program ({exc.strerror}).") from exc
    if b"\0" in raw:  # UTF-16 (a RobotStudio or Windows editor save) or binary
        line = raw[: raw.index(b"\0")].count(b"\n") + 1
        raise DataError(
            f"{p}: line {line}: a NUL byte: the "
            "file is UTF-16 encoded or binary; expected a text program (UTF-8, ASCII or "
            "the controller's 8-bit encoding): save it as UTF-8."
        )
    if not raw.strip():
        raise DataError(f"{p}: the program is empty; expected a {fmt} program.")
    if b"\r" in raw and b"\n" not in raw:  # (was: line 1: 'the file ends without')
        raise DataError(
            f"{p}: its lines end in CR only (an old Mac editor's); expected LF or CR LF "
            "line ends, as the controller writes them."
        )
    text = raw.decode("utf-8", errors="surrogateescape")
    try:
        code = code_only(text, fmt)
        check_values(code, fmt)  # nan, a unit: before the reader's own messages
        points, skipped = _READERS[fmt](code)  # its own messages first
        check_complete(code, fmt)
        check_positions(code, fmt)
    except DataError as exc:
        raise DataError(f"{p}: {exc}") from None
    unread = _unread(code, fmt)
    if unread:
        import warnings

        from kinecal.io._checks import DataWarning

        some = "; ".join(f"line {ln} ({what})" for ln, what in unread[:5])
        warnings.warn(
            f"{p}: {len(unread)} joint target(s) left as written, not numbers kinecal "
            f"can correct: {some}{' ...' if len(unread) > 5 else ''}; write their "
            "joint values as numbers to have them corrected.",
            DataWarning,
            stacklevel=2,
        )
    if not points:
        from kinecal.io._cartesian_programs import read_cartesian

        try:
            cartesian = read_cartesian(text, fmt)
        except DataError as exc:
            raise DataError(f"{p}: {exc}") from None
        if not cartesian:
            raise DataError(f"{p}: no joint or Cartesian target found ({fmt}).")
    return Program(str(p), fmt, text, tuple(points), skipped)


def _scale(prog: Program, robot: RobotDescription) -> Float:
    """Factors (n,) from the file's units to SI, per joint."""
    pris = robot.prismatic
    if _UNIT[prog.format] == "rad":
        return np.ones(robot.n_joints)
    return np.where(pris, 1e-3, np.pi / 180.0)


def program_joints(
    prog: Program, robot: RobotDescription, *, check: bool = True
) -> Float:
    """The program's joint targets as controller values (N, n) [rad, m]; ``check``:
    RAPID and KRL targets that look like radians refused or warned about
    (:func:`kinecal.io._program_checks.check_degrees`).

    Raises
    ------
    DataError
        A target with another number of joints than the robot (naming its line).
    """
    n = robot.n_joints
    for pt in prog.points:
        if len(pt.values) < n:
            raise DataError(
                f"{prog.path}: line {pt.line}: {pt.name} has {len(pt.values)} joint values; "
                f"{robot.name} has {n} joints."
            )
        if len(pt.values) > n and prog.format in ("fanuc-ls", "urscript"):
            raise DataError(
                f"{prog.path}: line {pt.line}: {pt.name} has {len(pt.values)} joint values; "
                f"{robot.name} has {n} joints."
            )
    check_fanuc_units(prog, robot.prismatic, robot.name)
    q = np.array([pt.values[:n] for pt in prog.points], dtype=np.float64).reshape(-1, n)
    if check:
        check_degrees(prog, q, robot.prismatic)
    return q * _scale(prog, robot)


def _format(value: float, decimals: int) -> str:
    s = f"{value:.{decimals}f}"
    return f"{0.0:.{decimals}f}" if float(s) == 0.0 else s  # no '-0.000'


def write_program(
    prog: Program,
    q_ctrl: Float,
    robot: RobotDescription,
    *,
    decimals: int | None = None,
    keep: np.ndarray | None = None,
    extra: list[tuple[int, int, str]] | None = None,
) -> str:
    """The program text with the joint targets replaced by ``q_ctrl`` (N, n) [rad, m]
    (and the ``extra`` edits (start, end, new text) made: Cartesian targets).

    Values are written with ``decimals`` decimals (default: as many as the file has, at
    least the format's usual: FANUC 3, URScript 8, RAPID and KRL 4); a value that reads
    the same at that precision keeps its original text, so a program written back
    unchanged is byte for byte the same. FANUC values keep their column (the number is
    right-aligned in the blanks before it). Rows where ``keep`` (N,) is True are left as
    they are; external axes (values after the n-th) are never touched.
    """
    q = np.asarray(q_ctrl, dtype=np.float64)
    n = robot.n_joints
    if q.shape != (len(prog.points), n):
        raise ValueError(
            f"q_ctrl must have shape ({len(prog.points)}, {n}); got {q.shape}."
        )
    vals = q / _scale(prog, robot)
    edits: list[tuple[int, int, str]] = []
    for k, pt in enumerate(prog.points):
        if keep is not None and keep[k]:
            continue
        for j in range(n):
            a, b = pt.spans[j]
            old = prog.text[a:b]
            dec = decimals
            if dec is None:
                dec = max(pt.decimals[j], _MIN_DECIMALS[prog.format])
            new = _format(float(vals[k, j]), dec)
            if float(_format(float(old), dec)) == float(new):
                continue  # the same value at the written precision
            if old[:1].isspace():  # FANUC: keep the column, and a blank after '='
                new = new.rjust(len(old)) if len(new) < len(old) else " " + new
            edits.append((a, b, new))
    edits = sorted(edits + list(extra or []))
    out = []
    last = 0
    for a, b, new in edits:
        out.append(prog.text[last:a])
        out.append(new)
        last = b
    out.append(prog.text[last:])
    return "".join(out)


def written_joints(prog: Program, text: str, robot: RobotDescription) -> Float:
    """The joint targets (N, n) [rad, m] a written program holds (read back)."""
    points, _ = _READERS[prog.format](code_only(text, prog.format))
    if not points:
        return np.zeros((0, robot.n_joints))
    return program_joints(
        Program(prog.path, prog.format, text, tuple(points), 0), robot, check=False
    )


def program_bytes(text: str) -> bytes:
    """The bytes of a program text read by :func:`read_program`."""
    return text.encode("utf-8", errors="surrogateescape")
