"""FANUC TP motions that move to a target shifted by a position register (issue 34).

``J P[3] 100% FINE Offset,PR[5]`` goes to P[3] shifted by PR[5]'s X, Y, Z, W, P, R in the
user frame (``M · T``); ``L P[4] 200mm/sec CNT50 Tool_Offset,PR[6]`` in the tool frame
(``T · M``). A bare ``Offset`` / ``Tool_Offset`` uses the register of the ``OFFSET
CONDITION PR[k]`` / ``TOOL_OFFSET CONDITION PR[k]`` executed last before it (here: written
last before it), in the frame the condition names (``,UFRAME[j]`` / ``,UTOOL[j]``) or
the target's own. The register's value comes from the controller's POSREG.VA (or
``posreg:`` in a YAML file); a register not given, uninitialized, with an indirect index
or in joint representation makes the offset unknown (``('?', why)``): the move is
counted and left with that reason (:func:`._cartesian_base.offset_targets`).
"""

from __future__ import annotations

import bisect
import re

__all__ = ["motion_offsets"]

_REF = r"\[((?:[^\[\]]|\[[^\]]*\])*)\]"
_MOVE = re.compile(rf"^\s*\d+\s*:\s*[JLCA]\s+(P|PR){_REF}[^;]*;", re.M)
_VIA = re.compile(rf"\n\s*:\s*(P|PR){_REF}")
_OPTION = re.compile(rf"(?<!\w)(Tool_Offset|Offset)\b(?:\s*,\s*(PR|VR){_REF})?", re.I)
_COND = re.compile(
    rf"^\s*\d+\s*:\s*(TOOL_OFFSET|OFFSET)\s+CONDITION\s+(PR|VR){_REF}"
    r"(?:\s*,\s*(?:UFRAME|UTOOL)\s*\[\s*(\d+)\s*\])?",
    re.I | re.M,
)
# Motion options whose target is no pose the reader can know: an incremental move's P[]
# is a displacement from where the robot is; a vision offset is measured as it runs.
_UNKNOWN = (
    (re.compile(r"(?<!\w)INC\b", re.I), "INC",
     "an incremental move (INC): its target is a displacement from where the robot "
     "is, not a pose"),
    (re.compile(r"(?<!\w)VOFFSET\b", re.I), "VOFFSET",
     "a vision offset (VOFFSET): its value is measured when the program runs"),
)  # fmt: skip
_VISION = "a vision register (VR[]): its value is measured when the program runs"


def register_index(ref: str) -> int | None:
    """The number of a register reference ``5``, ``GP1:5``, ``5:comment`` (None: an
    indirect index such as ``R[3]``)."""
    m = re.fullmatch(r"\s*(?:GP1\s*:\s*)?(\d+)\s*(?::.*)?", ref, re.S)
    return int(m.group(1)) if m else None


def _value(kind: str, ref: str, registers: dict, label: str) -> tuple:
    n = register_index(ref)
    reg = registers.get(n) if n is not None else None
    why = ""
    if n is None:
        why = "an indirect register index: its value is not known before it runs"
    elif reg is None:
        why = ("the offset register's value is in the controller (give the "
               "controller's POSREG.VA, or posreg: in a YAML file, with --frames)")  # fmt: skip
    elif reg.kind == "uninitialized":
        why = "the offset register is uninitialized in the registers given"
    elif reg.kind != "cartesian" or len(reg.values) < 6:  # joints
        why = ("the offset register holds joints: an offset in joint representation is "
               "not handled (make the register Cartesian)")  # fmt: skip
    if why or reg is None:
        return ("?", f"{label}: {why}")
    return (kind, *(float(v) for v in reg.values[:6]))


def motion_offsets(
    text: str, registers: dict | None
) -> dict[int, tuple[str, int | None, tuple | None, str, str]]:
    """Position of each motion target reference (``P[n]`` / ``PR[n]`` right after the
    motion type, or on a circular move's second line) -> (``'P'`` or ``'PR'``, n (None:
    indirect), offset (None: none, a tuple for :func:`._cartesian_base.apply_offset`, or
    ``('?', why)``), its label (``'Offset,PR[5]'``), the frame number a condition names
    ('' for the target's own))."""
    regs = registers or {}
    conds: dict[str, list] = {"OFFSET": [], "TOOL_OFFSET": []}
    for c in _COND.finditer(text):  # in order: positions sorted
        ref = c.group(3) if c.group(2).upper() == "PR" else None  # VR: at run time
        conds[c.group(1).upper()].append((c.start(), ref, c.group(4) or ""))
    starts = {k: [c[0] for c in v] for k, v in conds.items()}
    out: dict[int, tuple[str, int | None, tuple | None, str, str]] = {}
    for m in _MOVE.finditer(text):
        refs = [(m.start(1), m.group(1).upper(), m.group(2))]
        end = m.end(2) + 1
        via = _VIA.search(m.group(0))
        if via and re.match(r"\s*\d+\s*:\s*C\s", m.group(0)):
            refs.append((m.start() + via.start(1), via.group(1).upper(), via.group(2)))
            end = m.start() + via.end()
        opt = _OPTION.search(text, end, m.end())
        offset: tuple | None = None
        label, frame = "", ""
        unknown = [
            (w, why) for pat, w, why in _UNKNOWN if pat.search(text, end, m.end())
        ]
        if unknown:
            label, why = unknown[0]
            offset = ("?", why)
        elif opt:
            kind = (
                "Tool_Offset" if opt.group(1).lower().startswith("tool") else "Offset"
            )
            if opt.group(2) is not None:
                label = f"{kind},{opt.group(2).upper()}[{opt.group(3)}]"
                offset = (
                    _value(kind, opt.group(3), regs, label)
                    if opt.group(2).upper() == "PR"
                    else ("?", f"{label}: {_VISION}")
                )
            else:
                last = bisect.bisect_left(starts[kind.upper()], m.start()) - 1
                label = f"{kind} (no {kind.upper()} CONDITION before it)"
                offset = ("?", f"{label}: the register it uses is not known")
                if last >= 0:
                    _, ref, frame = conds[kind.upper()][last]
                    label = f"{kind} (CONDITION {'PR' if ref else 'VR'}[{ref or ''}])"
                    offset = (
                        _value(kind, ref, regs, label)
                        if ref is not None
                        else ("?", f"{kind} (CONDITION VR[]): {_VISION}")
                    )
        for at, what, ref in refs:
            out[at] = (what, register_index(ref), offset, label, frame)
    return out
