"""FANUC position registers (issue 34): the controller's ``POSREG.VA`` read, the
motions of a TP program to ``PR[n]`` found with the user and tool frame active there,
and the corrected values written as a TP program that sets them.

A ``POSREG.VA`` (the text dump of ``$POSREG`` in a controller backup) holds, per motion
group and register, either joint values::

        [1,1] =   'HOME'   Group: 1
      J1 =    60.000 deg   J2 =   -50.000 deg   J3 =    10.000 deg
      J4 =   -10.000 deg   J5 =   -95.000 deg   J6 =   -50.000 deg

or a Cartesian position, with its configuration::

        [1,10] =   'PICK'
      Group: 1   Config: N U T, 0, 0, 0
      X:  -820.507   Y:  2309.503   Z:   945.836
      W:    90.594   P:    -1.149   R:  -160.248

or ``Uninitialized``; extended axes follow as ``EXT1: .. mm`` lines. A register holds no
frame: a motion to it uses the user and tool frames the program selected last
(``UFRAME_NUM=u``, ``UTOOL_NUM=t``). The corrected values go back to the controller as a
TP program of element assignments (``PR[i,j]=value``; a negative constant in
parentheses, as the teach pendant writes it); a changed configuration cannot be set so
and is named in a remark.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from kinecal.errors import DataError

__all__ = [
    "PositionRegister",
    "RegisterMotion",
    "read_position_registers",
    "register_motions",
    "registers_program",
]

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_VAL = rf"({_NUM}|\*+)"


@dataclass(frozen=True)
class PositionRegister:
    """One initialised register of motion group 1.

    Attributes
    ----------
    index, comment, line : ``PR[index]``, its comment, the 1-based line of its entry.
    joints : joint values as written (deg; mm for a linear axis), or None.
    cartesian : X, Y, Z [mm], W, P, R [deg], or None.
    config : the configuration text (``'N U T, 0, 0, 0'``) of a Cartesian register.
    """

    index: int
    comment: str
    line: int
    joints: tuple[float, ...] | None = None
    cartesian: tuple[float, ...] | None = None
    config: str | None = None


@dataclass(frozen=True)
class RegisterMotion:
    """A motion instruction to ``PR[index]`` (None: an indirect index, ``PR[R[3]]``):
    its line and the user / tool frame numbers selected before it (None: not set in
    the program, or set from a register)."""

    index: int | None
    line: int
    uframe: str | None
    utool: str | None


def _value(tok: str, path: str, line: int, what: str) -> float:
    if tok.startswith("*"):
        raise DataError(
            f"{path}: line {line}: {what} is not set ({tok}); expected a number."
        )
    return float(tok)


def read_position_registers(path: str | Path) -> dict[int, PositionRegister]:
    """The initialised registers of motion group 1 of a ``POSREG.VA``, by number.

    Raises
    ------
    DataError
        Not a ``$POSREG`` dump, or an entry that is not a joint or Cartesian position
        (the message names the file and the line).
    """
    from kinecal._outputs import note_input

    note_input(path)
    p = str(path)
    try:
        text = Path(path).read_bytes().decode("utf-8", errors="replace")
    except OSError as exc:
        raise DataError(f"{p}: cannot read the registers ({exc.strerror}).") from None
    if not re.search(r"\$POSREG\b", text):
        raise DataError(
            f"{p}: no $POSREG; expected the controller's POSREG.VA (the position "
            "registers of a backup, as text)."
        )
    lines = text.splitlines()
    heads = [
        (i, m)
        for i, ln in enumerate(lines)
        if (m := re.match(r"\s*\[\s*(\d+)\s*,\s*(\d+)\s*\]\s*=\s*'([^']*)'(.*)$", ln))
    ]
    out: dict[int, PositionRegister] = {}
    for k, (i, m) in enumerate(heads):
        group, index, comment, rest = int(m[1]), int(m[2]), m[3], m[4]
        if "Uninitialized" in rest or group != 1:
            continue
        end = heads[k + 1][0] if k + 1 < len(heads) else len(lines)
        body = "\n".join(lines[i + 1 : end])
        at = i + 1
        joints = re.findall(rf"\bJ(\d+)\s*=\s*{_VAL}\s*(deg|mm)", body)
        cfg = re.search(r"\bConfig\s*:\s*([^\n]*)", body)
        if joints and cfg is None:
            order = [int(j) for j, _, _ in joints]
            if order != list(range(1, len(order) + 1)):
                raise DataError(
                    f"{p}: line {at}: PR[{index}] lists joints {order}; expected J1, "
                    "J2, ... in order."
                )
            vals = tuple(_value(v, p, at, f"PR[{index}] J{j}") for j, v, _ in joints)
            out[index] = PositionRegister(index, comment, at, joints=vals)
            continue
        xyz = re.search(rf"\bX:\s*{_VAL}\s+Y:\s*{_VAL}\s+Z:\s*{_VAL}", body)
        wpr = re.search(rf"\bW:\s*{_VAL}\s+P:\s*{_VAL}\s+R:\s*{_VAL}", body)
        if cfg is None or xyz is None or wpr is None:
            raise DataError(
                f"{p}: line {at}: PR[{index}] is neither a joint position (J1 = .. deg) "
                "nor a Cartesian one (Group: 1 Config: .., X: .. Y: .. Z: .., W: .. "
                "P: .. R: ..)."
            )
        vals = tuple(
            _value(v, p, at, f"PR[{index}] {key}")
            for key, v in zip("XYZWPR", (*xyz.groups(), *wpr.groups()), strict=True)
        )
        out[index] = PositionRegister(
            index, comment, at, cartesian=vals, config=cfg[1].strip()
        )
    return out


def register_motions(text: str) -> list[RegisterMotion]:
    """The motion instructions of a TP program to a position register, in order, with
    the user and tool frame numbers selected before each (``Offset,PR[n]`` and
    ``Tool_Offset,PR[n]`` are offsets, not targets)."""
    uf: str | None = None
    ut: str | None = None
    out = []
    for no, ln in enumerate(text.splitlines(), 1):
        body = ln.split("!", 1)[0] if re.match(r"\s*\d+\s*:\s*!", ln) else ln
        for key, m in re.findall(r"\b(UFRAME_NUM|UTOOL_NUM)\s*=\s*(\S+?)\s*;", body):
            val = m if m.isdigit() else None  # from a register: unknown here
            if key == "UFRAME_NUM":
                uf = val
            else:
                ut = val
        mot = re.match(r"\s*\d+\s*:\s*[JLCA]\s+PR\[\s*(?:GP\d+\s*:\s*)?([^\]:]*)", body)
        if mot:
            idx = mot[1].strip()
            out.append(RegisterMotion(int(idx) if idx.isdigit() else None, no, uf, ut))
    return out


def _constant(v: float, decimals: int) -> str:
    s = f"{abs(v):.{decimals}f}"
    return f"(-{s})" if v < 0 and float(s) != 0 else s


def registers_program(
    name: str, source: str, values: list[tuple[PositionRegister, tuple[float, ...]]],
    notes: list[str], decimals: int = 3,
) -> str:  # fmt: skip
    """A TP program (``.LS``) that sets the registers to ``values`` (per register, the
    corrected joints or X, Y, Z, W, P, R as written), with ``notes`` as remarks."""
    prog = re.sub(r"[^A-Z0-9_]", "_", name.upper()) or "KC_PR"
    if not prog[0].isalpha():
        prog = "KC_" + prog
    body = [f"!kinecal: position registers of {Path(source).name} ;"]
    body += [f"!{n.replace(';', ',')[:60]} ;" for n in notes]
    for reg, vals in values:
        body.append(f"!PR[{reg.index}] {reg.comment} ;")
        body += [
            f"PR[{reg.index},{j}]={_constant(v, decimals)} ;"
            for j, v in enumerate(vals, 1)
        ]
    head = [
        f"/PROG  {prog[:36]}",
        "/ATTR",
        "OWNER\t\t= MNEDITOR;",
        'COMMENT\t\t= "kinecal PR";',
        f"LINE_COUNT\t= {len(body)};",
        "PROTECT\t\t= READ_WRITE;",
        "DEFAULT_GROUP\t= *,*,*,*,*;",
        "/MN",
    ]
    mn = [f"{i:4d}:  {ln}" for i, ln in enumerate(body, 1)]
    return "\r\n".join([*head, *mn, "/POS", "/END", ""])
