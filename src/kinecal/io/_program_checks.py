"""Checks of a robot program's targets beside what its reader parses
(:mod:`._programs`): damage the readers would pass over without a word.

- A joint value written ``nan`` or ``inf`` is not a number the readers match: the
  target (a URScript ``movej([nan, ...])``, a RAPID ``jointtarget``) was skipped as if
  it were an expression, and the program was written back with that target
  uncorrected and unreported.
- A FANUC position whose joint value has another unit than ``deg`` / ``mm`` (``rad``,
  none) was named as "joints [1, 2, 3, 4, 6] not in order".
- A FANUC ``/POS`` section with ``P[n]`` twice (both were corrected: which one the
  controller keeps is not said), or a move to a ``P[n]`` that ``/POS`` lacks (the
  controller stops there: "uninitialized position").
- A RAPID ``jointtarget`` or KRL ``AXIS`` written in radians: both formats hold degrees
  (RAPID ``robjoint``: each axis "in degrees from the calibration position"; mm for a
  linear axis), and radians were read as degrees, a pose within 6.3 deg of zero on
  every joint: "compensated" and written back (:func:`check_degrees`).
"""

from __future__ import annotations

import re
import warnings
from typing import Any

import numpy as np

from kinecal.errors import DataError
from kinecal.io._cartesian_base import _line

__all__ = [
    "check_degrees",
    "check_fanuc_units",
    "check_krl_axes",
    "check_positions",
    "check_values",
]

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
# nan / inf where a value stands: in a list ('[', ',', '{'), after a FANUC 'Jn =' or a
# KRL axis name (not after a URScript keyword argument: v=inf is no joint value).
_NON_FINITE = re.compile(
    r"(?:[\[,{]|\bJ\d+[ \t]*=|\b[AE]\d)[ \t]*([-+]?(?:nan|inf(?:inity)?))"
    r"(?=[ \t]*(?:[,\]};]|deg\b|mm\b|$))",
    re.I | re.M,
)


def check_values(code: str, fmt: str) -> None:
    """Raise :class:`DataError` (``line N: ...``) for a value ``nan`` / ``inf`` or a
    FANUC joint value in another unit; ``code``: the program without its comments."""
    m = _NON_FINITE.search(code)
    if m is not None:
        raise DataError(
            f"line {_line(code, m.start(1))}: {m.group(1)!r} is not a value a robot "
            "can move to; expected a finite number."
        )
    if fmt == "krl":
        check_krl_axes(code)
    if fmt != "fanuc-ls":
        return
    for n, at, body in _positions(code):
        for j in re.finditer(rf"\bJ(\d+)\s*=\s*({_NUM})[ \t]*([A-Za-z/]*)", body):
            if j.group(3) not in ("deg", "mm"):
                unit = f" {j.group(3)}" if j.group(3) else " without a unit"
                raise DataError(
                    f"line {_line(code, at + j.start())}: P[{n}] J{j.group(1)} = "
                    f"{j.group(2)}{unit}; expected deg (mm for a linear axis), as a "
                    "controller writes it."
                )


_AXIS_ITEM = re.compile(r"\b[AE]\d+\b")


def check_krl_axes(code: str) -> None:
    """Raise :class:`DataError` for a KRL axis aggregate (``{A1 .., A2 .., E1 ..}``)
    whose components are not ``NAME value`` with a number (``A1 abc``; ``A1 15,5``, a
    decimal comma, read as A1 = 15), name an axis twice or out of order, or a declared
    one (``XP1={..}``) without all of A1..A6: the reader took such a target for a
    partial aggregate and left it unread and unreported, or read 15,5 as 15."""
    for m in re.finditer(r"\{([^{}]*)\}", code):
        body = m.group(1)
        if not _AXIS_ITEM.search(body) or re.search(r"\bX\s", body):
            continue  # not an axis aggregate (a frame, a POS, FDAT, PDAT)
        seen: list[str] = []
        for item in re.finditer(r"[^,]+", body):
            at = _line(code, m.start(1) + item.start())
            it = re.fullmatch(r"\s*([A-Za-z_]\w*)\s+(\S.*?)\s*", item.group())
            if it is None:
                raise DataError(
                    f"line {at}: {item.group().strip()!r} in the axis aggregate is no "
                    "component 'NAME value'; expected e.g. A1 15.5 (a decimal comma?)."
                )
            name, value = it.group(1).upper(), it.group(2)
            if not _AXIS_ITEM.fullmatch(name):
                continue
            if re.fullmatch(_NUM, value) is None:
                raise DataError(
                    f"line {at}: {name} {value!r} is not a number; expected the "
                    "axis value in degrees (mm for a linear axis)."
                )
            if name in seen:
                raise DataError(
                    f"line {at}: {name} is given twice in the axis aggregate; expected "
                    "each axis once."
                )
            seen.append(name)
        axes = [int(a[1:]) for a in seen if a[0] == "A"]
        if axes != sorted(axes):
            raise DataError(
                f"line {_line(code, m.start())}: the axis aggregate lists A{axes}; "
                "expected A1, A2, ... in order."
            )
        head = code[max(0, m.start() - 80) : m.start()]
        if re.search(r"\w\s*=\s*$", head) and axes and axes != list(range(1, 7)):
            missing = sorted(set(range(1, 7)) - set(axes))
            raise DataError(
                f"line {_line(code, m.start())}: the declared axis aggregate lacks "
                f"{', '.join(f'A{k}' for k in missing)}; expected A1..A6 (a "
                "declaration holds every axis)."
            )


def check_positions(code: str, fmt: str) -> None:
    """Raise :class:`DataError` for a FANUC ``P[n]`` defined twice, or moved to but not
    defined (checked once the program is known to be complete)."""
    if fmt != "fanuc-ls":
        return
    defined: dict[int, int] = {}
    for n, at, _ in _positions(code):
        if n in defined:
            raise DataError(
                f"line {_line(code, at)}: P[{n}] is defined twice in /POS (first on "
                f"line {defined[n]}); expected each position once."
            )
        defined[n] = _line(code, at)
    pos = re.search(r"^/POS\b", code, re.M)
    moves = r"^\s*\d+\s*:\s*[JLCA]\s+([^;\n]*)"
    for mv in re.finditer(moves, code[: pos.start() if pos else len(code)], re.M):
        for ref in re.finditer(r"(?<![A-Za-z])P\[\s*(\d+)", mv.group(1)):
            if int(ref.group(1)) not in defined:
                have = ", ".join(f"P[{k}]" for k in sorted(defined)) or "none"
                raise DataError(
                    f"line {_line(code, mv.start(1) + ref.start())}: a move to "
                    f"P[{ref.group(1)}], which /POS does not define (it has {have}); "
                    "expected every position the program moves to."
                )


def _positions(code: str) -> list[tuple[int, int, str]]:
    """(n, offset, body) of each ``P[n]{ body }`` of the /POS section."""
    pos = re.search(r"^/POS\b", code, re.M)
    if pos is None:
        return []
    rec = r"\bP\[\s*(\d+)[^\]]*\]\s*\{(.*?)\}"
    return [
        (int(m.group(1)), pos.end() + m.start(), m.group(2))
        for m in re.finditer(rec, code[pos.end() :], re.S)
    ]


def check_fanuc_units(prog: Any, prismatic: np.ndarray, name: str) -> None:
    """Raise :class:`DataError` for a FANUC joint value whose unit is not its joint's:
    ``mm`` on a revolute joint or ``deg`` on a linear one (``J1 = 10.000 mm`` on an
    arm's first axis was read as 10 deg)."""
    if prog.format != "fanuc-ls":
        return
    for pt in prog.points:
        for k, (_, b) in enumerate(pt.spans[: len(prismatic)]):
            unit = re.match(r"\s*(deg|mm)", prog.text[b : b + 16])
            want = "mm" if prismatic[k] else "deg"
            if unit is not None and unit.group(1) != want:
                kind = "linear" if prismatic[k] else "revolute"
                raise DataError(
                    f"{prog.path}: line {_line(prog.text, b)}: {pt.name} J{k + 1} = "
                    f"{pt.values[k]:g} {unit.group(1)}; J{k + 1} of {name} is "
                    f"{kind}: expected {want} (a position of another robot or group?)."
                )


_DEGREE_FORMATS = {"rapid": "RAPID jointtarget", "krl": "KRL axis aggregate"}


def check_degrees(prog: Any, values: np.ndarray, prismatic: np.ndarray) -> None:
    """A RAPID or KRL program (``prog``) whose joint targets ``values`` (N, n, as
    written) look like radians: every revolute value within +-2 pi on an arm of at least
    6 revolute joints, some not whole degrees (radians are, but for 0, never whole
    numbers; a zero, home or mastering pose, [0, 0, 0, 0, 30, 0], a joint jogged 5 deg
    from it, are whole degrees and pass). Refused (DataError) where the targets differ
    (no program moves a robot by under 12.6 deg per joint in all); one pose (or copies
    of it) is a warning: it may be a taught pose near every joint's zero."""
    kind = _DEGREE_FORMATS.get(prog.format)
    rev = ~np.asarray(prismatic, bool)
    if kind is None or np.count_nonzero(rev) < 6 or values.shape[0] == 0:
        return
    v = values[:, rev]
    if np.abs(v).max() > 2 * np.pi + 1e-9 or (np.abs(v - np.round(v)) <= 1e-6).all():
        return
    first = prog.points[0]
    text = (
        f"{prog.path}: line {first.line}: {first.name}: every joint value of the "
        f"program's {values.shape[0]} joint targets is within ±{2 * np.pi:.2f} "
        f"({v.min():g} .. {v.max():g}), which looks like radians; a {kind} holds "
        "degrees (mm for a linear axis)"
    )
    if np.ptp(v, axis=0).max() > 0.05:
        raise DataError(f"{text}: convert them (deg = rad x 180/pi).")
    warnings.warn(
        f"{text}: they are read as degrees; if they are radians, convert them.",
        stacklevel=3,
    )
