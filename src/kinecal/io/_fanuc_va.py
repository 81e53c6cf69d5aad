"""FANUC controller variable dumps (``.VA``, the text form of system variables a controller
backup holds) read for ``kinecal compensate``: the position registers of ``POSREG.VA``
(``$POSREG``) and the user and tool frames of ``SYSFRAME.VA`` (``$MNUFRAME``,
``$MNUTOOL``) (issue 34).

The layout, as controllers write it (one variable per block, its header line first)::

    [*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,100] OF Position Reg
        [1,1] =   'HOME'   Group: 1
      J1 =    60.000 deg   J2 =   -50.000 deg   J3 =    10.000 deg
      J4 =   -10.000 deg   J5 =   -95.000 deg   J6 =   -50.000 deg

        [1,2] =   '' Uninitialized
        [1,10] =   'PICK'
      Group: 1   Config: N U T, 0, 0, 0
      X:  -820.507   Y:  2309.503   Z:   945.836
      W:    90.594   P:    -1.149   R:  -160.248
      EXT1:  ******** mm

An element ``[group, index]`` holds joints (``Group: g`` on the element line, ``Jk = v
deg|mm``) or a Cartesian position (``Group: g   Config: ...``, then X Y Z [mm] and W P R
[deg]), or is ``Uninitialized``. Numbers may drop the leading zero (``-.649``);
``********`` is a value the controller could not print. A Cartesian register holds no
user or tool frame: the motion that uses it is in the frames active at that line.
``SYSFRAME.VA`` prints ``$MNUFRAME`` / ``$MNUTOOL`` elements ``[g, i] =`` with the same
Cartesian block (no comment). Only group 1 (the robot) is read.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from kinecal.errors import DataError

__all__ = [
    "Register",
    "is_va_text",
    "read_posreg",
    "read_va_frames",
    "register_program",
]

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_HEAD = re.compile(r"^\[\*?(\w*)\*?\](\$\w+)\b", re.M)
_ELEM = re.compile(r"^\s*\[\s*(\d+)\s*,\s*(\d+)\s*\]\s*=(.*)$")
_CART = re.compile(r"^\s*Group:\s*(\d+)\s+Config:\s*(.*?)\s*$")


@dataclass(frozen=True)
class Register:
    """One position register (group 1).

    Attributes
    ----------
    index : its number n of ``PR[n]``.
    comment : its comment as written.
    kind : 'cartesian', 'joint' or 'uninitialized'.
    values : X, Y, Z [mm], W, P, R [deg], or the joints [deg or mm].
    config : the CONFIG text (``'N U T, 0, 0, 0'``) of a Cartesian register, else ''.
    line : 1-based line of its element in the file.
    """

    index: int
    comment: str
    kind: str
    values: tuple[float, ...]
    config: str
    line: int


def is_va_text(text: str) -> bool:
    """Whether ``text`` is a FANUC variable dump (a ``[*NAME*]$VAR`` header)."""
    return _HEAD.search(text) is not None


def _blocks(text: str) -> dict[str, tuple[int, list[str]]]:
    """Variable name -> (1-based line of its header, its lines after the header)."""
    lines = text.splitlines()
    out: dict[str, tuple[int, list[str]]] = {}
    cur: list[str] | None = None
    for i, ln in enumerate(lines):
        m = _HEAD.match(ln)
        if m:
            cur = []
            out.setdefault(m.group(2).upper(), (i + 1, cur))
        elif cur is not None:
            cur.append(ln)
    return out


def _number(path: str, line: int, token: str, what: str) -> float:
    if "*" in token:
        raise DataError(
            f"{path}: line {line}: {what} is '{token}' (not printable by the controller); "
            "expected a number."
        )
    return float(token)


def _cartesian(path: str, body: list[str], k: int, start: int) -> tuple[tuple, int]:
    """X, Y, Z, W, P, R from the lines after a ``Group: g Config:`` line at ``k``."""
    text = " ".join(body[k + 1 : k + 3])
    vals = []
    for key in "XYZWPR":
        m = re.search(rf"(?<!\w){key}:\s*({_NUM}|\*+)", text)
        at = start + k + 2 + (key in "WPR")
        if m is None:
            raise DataError(
                f"{path}: line {at}: expected '{key}: <number>' (X, Y, Z "
                "[mm] and W, P, R [deg] on the two lines after 'Group: g   Config: ...')."
            )
        vals.append(_number(path, at, m.group(1), key))
    return tuple(vals), k + 3


def _elements(path: str, start: int, body: list[str]) -> list[tuple]:
    """(group, index, comment, kind, values, config, line) of an array's elements."""
    out: list[tuple] = []
    k = 0
    while k < len(body):
        m = _ELEM.match(body[k])
        if m is None:
            k += 1
            continue
        g, i, rest = int(m.group(1)), int(m.group(2)), m.group(3)
        line = start + k + 1
        cm = re.match(r"\s*'([^']*)'", rest)
        comment = cm.group(1) if cm else ""
        rest = rest[cm.end() :] if cm else rest
        k += 1
        if "Uninitialized" in rest:
            out.append((g, i, comment, "uninitialized", (), "", line))
            continue
        inline = _CART.match(rest.replace("Group:", "\nGroup:", 1).split("\n")[-1])
        if inline is not None and inline.group(2).strip():  # Config on the element line
            vals6, k = _cartesian(path, body, k - 1, start)
            out.append((g, i, comment, "cartesian", vals6, inline.group(2), line))
            continue
        if re.search(r"\bGroup:\s*\d+", rest):  # joints: Jk = v lines follow
            vals: dict[int, float] = {}
            while k < len(body) and not _ELEM.match(body[k]) and body[k].strip():
                for jm in re.finditer(rf"\bJ(\d+)\s*=\s*({_NUM}|\*+)", body[k]):
                    vals[int(jm.group(1))] = _number(
                        path, start + k + 1, jm.group(2), f"J{jm.group(1)}"
                    )
                k += 1
            if not vals or sorted(vals) != list(range(1, len(vals) + 1)):
                raise DataError(
                    f"{path}: line {line}: [{g},{i}] holds joints, but not J1 .. Jn "
                    "('Jk = <number> deg' lines)."
                )
            joints = tuple(vals[j] for j in sorted(vals))
            out.append((g, i, comment, "joint", joints, "", line))
            continue
        while k < len(body) and not body[k].strip():
            k += 1
        cart = _CART.match(body[k]) if k < len(body) else None
        if cart is None:
            raise DataError(
                f"{path}: line {line}: [{g},{i}]: expected 'Group: g   Config: ...' "
                "and X..R lines, joints 'Jk = ...', or 'Uninitialized'."
            )
        if not cart.group(2).strip():  # a group without a robot (no configuration)
            out.append((g, i, comment, "uninitialized", (), "", line))
            k += 1
            continue
        vals6, k = _cartesian(path, body, k, start)
        out.append((g, i, comment, "cartesian", vals6, cart.group(2).strip(), line))
    return out


def read_posreg(path: str, text: str) -> dict[int, Register]:
    """The group-1 position registers of a ``POSREG.VA`` text: {n: Register}.

    Raises
    ------
    DataError
        No ``$POSREG`` variable, or a malformed element (naming the file and line).
    """
    blocks = _blocks(text)
    if "$POSREG" not in blocks:
        raise DataError(
            f"{path}: no '[*POSREG*]$POSREG' variable; expected the controller's "
            "POSREG.VA (position registers)."
        )
    start, body = blocks["$POSREG"]
    out = {}
    for g, i, comment, kind, vals, cfg, line in _elements(path, start, body):
        if g == 1:
            out[i] = Register(i, comment, kind, vals, cfg, line)
    return out


def read_va_frames(path: str, text: str) -> tuple[dict, dict]:
    """User and tool frames of a ``SYSFRAME.VA`` text (group 1): ({'i': (x, y, z, w, p,
    r)}, {'i': ...}) in mm and deg; uninitialized ones left out.

    Raises
    ------
    DataError
        Neither ``$MNUFRAME`` nor ``$MNUTOOL``, or a malformed element.
    """
    blocks = _blocks(text)
    if "$MNUFRAME" not in blocks and "$MNUTOOL" not in blocks:
        raise DataError(
            f"{path}: no '$MNUFRAME' or '$MNUTOOL' variable; expected the controller's "
            "SYSFRAME.VA (user and tool frames)."
        )
    out: tuple[dict, dict] = ({}, {})
    for which, name in enumerate(("$MNUFRAME", "$MNUTOOL")):
        if name not in blocks:
            continue
        start, body = blocks[name]
        for g, i, _, kind, vals, _, _ in _elements(path, start, body):
            if g == 1 and kind == "cartesian":
                out[which][str(i)] = vals
    return out


def register_program(name: str, registers: dict[int, Register], source: str) -> str:
    """A TP program (``.LS``, CRLF) that writes corrected register values element by
    element, ``PR[n,j]=v ;``: run once on the controller (after loading it, as the
    corrected program) it sets X..R (or the joints) and keeps each register's CONFIG,
    comment and representation, as FANUC's element assignment does. ``name``: the
    program name (letters, digits, '_'), ``source``: what it was made from (a comment).
    """
    body = [f"!kinecal: corrected PR of {source[:20]}"[:32], "!run once, then delete"]
    for n in sorted(registers):
        r = registers[n]
        body += [f"PR[{n},{j + 1}]={v:.3f}" for j, v in enumerate(r.values)]
    mn = [f"{k + 1:4d}:  {ln} ;" for k, ln in enumerate(body)]
    head = [
        f"/PROG  {name}",
        "/ATTR",
        "OWNER\t\t= MNEDITOR;",
        'COMMENT\t\t= "kinecal PR";',
        f"LINE_COUNT\t= {len(mn)};",
        "PROTECT\t\t= READ_WRITE;",
        "DEFAULT_GROUP\t= *,*,*,*,*;",
        "/MN",
    ]
    return "\r\n".join([*head, *mn, "/POS", "/END", ""])
