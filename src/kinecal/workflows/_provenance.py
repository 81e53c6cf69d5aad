"""Double compensation: ``kinecal compensate`` marks what it writes, and refuses to
compensate its own output again.

A corrected program loaded back into ``compensate`` (a copy taken from the controller,
a file picked from the wrong folder) would have its joint targets corrected a second
time: the real robot then misses them by the correction itself, silently. Every program
``compensate`` writes holds one comment line, :data:`MARK` (FANUC: a remark as the last
line of ``/MN``, ``LINE_COUNT`` counted up; RAPID before the last ``ENDMODULE``; KRL
before the last ``END`` / ``ENDDAT``; URScript at the end), in the format's own comment
syntax, so the vendor's loaders and kinecal's readers skip it. ``CORRECTED.csv`` carries
its provenance in its columns (``jK_deg_program``, ``err_mm``, ``status``): no comment
line, which would break CSV readers that take the first line as the header.

On input, a program holding the mark in a comment, or a TARGETS file with the
``_program`` columns, is refused (exit 2). The override is explicit and in the file: the
message names the line (or the columns) to remove, for the rare program that is meant to
be compensated again (e.g. taught anew on top of a corrected one).
"""

from __future__ import annotations

import re
from collections.abc import Iterable

from kinecal.errors import DataError

__all__ = ["MARK", "mark_compensated", "refuse_compensated_program", "refuse_corrected"]

# FANUC remarks hold at most 32 characters (``!`` and the text).
MARK = "kinecal compensated"
_TAIL = "; compensate the original, not this"
_COMMENT = {"fanuc-ls": "!", "rapid": "!", "krl": ";", "urscript": "#"}
# The line the mark goes before (the last match), per format; None: the end of the file.
_BEFORE = {
    "rapid": r"^[ \t]*ENDMODULE\b",
    "krl": r"^[ \t]*(?:END|ENDDAT|ENDFCT)\b",
    "urscript": None,
}


def _eol(text: str) -> str:
    return "\r\n" if "\r\n" in text else "\n"


def _fanuc(text: str) -> str:
    """The mark as the last line of ``/MN`` (numbered after the last one), with
    ``LINE_COUNT`` counted up (where the file has it)."""
    eol = _eol(text)
    mn = re.search(r"^/MN\b[^\n]*\n", text, re.M)
    stop = re.search(r"^/(?:POS|END)\b", text, re.M)
    if mn is None or stop is None or stop.start() < mn.end():
        return text + ("" if text.endswith("\n") or not text else eol)
    body = text[mn.end() : stop.start()]
    numbers = [int(n) for n in re.findall(r"^[ \t]*(\d+)[ \t]*:", body, re.M)]
    n = (max(numbers) if numbers else 0) + 1
    line = f"{n:4d}:  !{MARK} ;{eol}"
    out = text[: stop.start()] + line + text[stop.start() :]
    count = re.compile(r"^(LINE_COUNT[ \t]*=[ \t]*)(\d+)", re.M)
    return (
        count.sub(lambda m: f"{m.group(1)}{n}", out[: mn.start()], count=1)
        + out[mn.start() :]
    )


def mark_compensated(text: str, fmt: str) -> str:
    """``text`` (a corrected program of format ``fmt``) with the :data:`MARK` comment
    line added (see the module docstring for where); every other byte kept."""
    if fmt == "fanuc-ls":
        return _fanuc(text)
    eol = _eol(text)
    line = f"{_COMMENT[fmt]} {MARK}{_TAIL}"
    pattern = _BEFORE.get(fmt)
    found = list(re.finditer(pattern, text, re.M | re.I)) if pattern else []
    if not found:
        lead = "" if text.endswith("\n") or not text else eol
        return f"{text}{lead}{line}{eol}"
    at = found[-1].start()
    indent = re.match(r"[ \t]*", text[at:]).group(0)  # type: ignore[union-attr]
    return f"{text[:at]}{indent}{line}{eol}{text[at:]}"


def refuse_compensated_program(path: str, text: str, fmt: str) -> None:
    """Refuse a program that holds :data:`MARK` in a comment: ``compensate`` wrote it,
    and its targets are corrected already.

    Raises
    ------
    DataError
        Naming the file and the line of the mark.
    """
    from kinecal.io._cartesian_base import code_only

    if MARK not in text:
        return
    code = code_only(text, fmt)
    for m in re.finditer(re.escape(MARK), text):
        if code[m.start()] != " ":  # in the code (a string, a name): not the mark
            continue
        line = text.count("\n", 0, m.start()) + 1
        raise DataError(
            f"{path}: line {line}: '{MARK}': a program kinecal compensate wrote; its "
            "targets are corrected already, and correcting them again applies the "
            "correction twice (the robot then misses every target by it). Compensate "
            "the original program; to compensate this one anyway (it was taught anew), "
            "delete that comment line."
        )


def refuse_corrected(path: str, header: Iterable[str]) -> None:
    """Refuse a TARGETS file that is ``compensate``'s CORRECTED.csv (its
    ``jK_<unit>_program`` columns): its joint columns hold the corrected joints, not
    the program's, and compensating it again would write the ``_program`` columns twice
    (the program's joints lost).

    Raises
    ------
    DataError
        Naming the file and the columns.
    """
    cols = list(header)
    program = [c for c in cols if re.fullmatch(r"j\d+_(?:deg|mm|rad|m)_program", c)]
    if not program:
        return
    raise DataError(
        f"{path}: columns {', '.join(program[:2])}{'..' if len(program) > 2 else ''}: a "
        "file kinecal compensate wrote (CORRECTED.csv); its joint columns hold the "
        "corrected joints already. Compensate the original targets (the program's "
        f"joints are in the _program columns); to compensate this file anyway, remove "
        "its _program columns."
    )
