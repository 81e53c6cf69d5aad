"""Cartesian targets in robot programs: read them with their frames and configuration,
write corrected values back in place (issue 34).

==========  ==============================================  ==============  ============
format      Cartesian target                                orientation     frames
==========  ==============================================  ==============  ============
fanuc-ls    ``/POS`` ``P[n]{ GP1: UF : u, UT : t, CONFIG :  W, P, R [deg]:  UF/UT ids
            'N U T, 0, 0, 0', X = .. mm, ... R = .. deg}``  Rz(R)Ry(P)Rx(W)
krl         ``{X .., Y .., Z .., A .., B .., C .., S .., T  A, B, C [deg]:  FDAT
            ..}`` (POS, E6POS, FRAME)                       Rz(A)Ry(B)Rx(C) ``FP<n>`` of
                                                                            ``XP<n>``
rapid       ``robtarget name := [[x, y, z], [q1..q4],       quaternion      tool, wobj
            [cf1, cf4, cf6, cfx], [eax]]``, and inline      (w, x, y, z)    of the moves
            ``MoveL [[..], ..]``                                            using it
urscript    ``movel/movej/movep(p[x, y, z, rx, ry, rz]``    rotation vector ``set_tcp``
            and ``global Name_p=p[...]`` (Polyscope, with   [rad]
            ``Name_q=[...]``)
==========  ==============================================  ==============  ============

Also: FANUC motions to position registers ``PR[n]`` (one target per register, in the
``UFRAME_NUM``/``UTOOL_NUM`` active at its moves; its value from the controller's
POSREG.VA, :mod:`._fanuc_va`); FANUC moves with ``Offset,PR[k]`` / ``Tool_Offset,PR[k]``
(:mod:`._fanuc_offsets`); RAPID moves to ``Offs(p, dx, dy, dz)`` /
``RelTool(p, dx, dy, dz \\Rx \\Ry \\Rz)`` (the robtarget corrected for its own move,
else for its first offset; other offsets follow it and are checked, :mod:`._cartesian_rapid`,
:func:`._cartesian_base.offset_targets`);
URScript pose variables assigned anywhere and ``pose_trans(FEATURE, target)``
(:mod:`._cartesian_urscript`).

Units: mm and deg (URScript m and rad). A target is returned with its pose in its own
frame, the frame ids it names and its configuration as written; which frame an id means
is for the caller (:mod:`kinecal.workflows._compensate`).
"""

from __future__ import annotations

import re
from dataclasses import replace

import numpy as np

from kinecal.errors import DataError
from kinecal.geometry import matrix_to_euler_zyx, matrix_to_quat_wxyz, so3_log
from kinecal.io._cartesian_base import (
    _NUM,
    CartesianPoint,
    _decimals,
    _line,
    _make,
    apply_offset,
    code_only,
    offset_targets,
    point_pose,
    remove_offset,
)
from kinecal.io._cartesian_rapid import _rapid, rapid_frames
from kinecal.io._cartesian_urscript import _urscript, urscript_features
from kinecal.io._fanuc_offsets import motion_offsets
from kinecal.typing import Float, Pose

__all__ = [
    "CartesianPoint",
    "apply_offset",
    "cartesian_edits",
    "cartesian_numbers",
    "point_pose",
    "rapid_frames",
    "read_cartesian",
    "remove_offset",
    "urscript_features",
]

_MIN_DECIMALS = {"fanuc-ls": 3, "krl": 4, "rapid": 6, "urscript": 8}


# ------------------------------------------------------------------ FANUC
def _fanuc_config(text: str, at: int, name: str, cfg: str) -> tuple:
    head, *turns = (s.strip() for s in cfg.split(","))
    letters = tuple(head.replace(" ", ""))
    ok = len(letters) == 3 and letters[0] in "NF" and letters[1] in "UD"
    ok = ok and letters[2] in "TB" and len(turns) == 3
    try:
        t = tuple(int(x) for x in turns)
    except ValueError:
        ok = False
    if not ok:
        where = f"line {_line(text, at)}: " if at or text != cfg else ""
        raise DataError(
            f"{where}{name} CONFIG {cfg!r}; expected 'N|F U|D T|B, "
            "t1, t4, t6' (turn numbers integers)."
        )
    return (*letters, *t)


# UFRAME_NUM / UTOOL_NUM, as a German-language controller writes them too
_UF, _UT = "(?:UFRAME_NUM|BENUTZER_NUM)", "(?:UTOOL_NUM|WKZ_NUM)"


def _active(text: str, pos: int, what: str) -> str | None:
    """The ``UFRAME_NUM`` / ``UTOOL_NUM`` set last before ``pos`` ('' for none, None for
    one set from a register or expression)."""
    last = ""
    for m in re.finditer(rf"^\s*\d+\s*:\s*{what}\s*=\s*([^;]*);", text[:pos], re.M):
        last = m.group(1).strip()
    return last if last == "" or last.isdigit() else None


def _fanuc_registers(
    text: str, registers: dict | None, offsets: dict
) -> list[CartesianPoint]:
    """The position registers ``PR[n]`` motion instructions move to, one target per
    register (at its first use), with the frames active at its uses; its value from
    ``registers`` ({n: :class:`kinecal.io._fanuc_va.Register`}, a controller's
    POSREG.VA), else counted and left."""
    uses: dict[str, list[tuple[int, str | None, str | None, str]]] = {}
    pr_ref = r"(PR\[((?:[^\[\]]|\[[^\]]*\])*)\])"
    pat = rf"^\s*\d+\s*:\s*[JLCA]\s+{pr_ref}"
    # A circular move's second point is on the next line: ``3:C PR[2] \n : PR[3] ..;``
    via = rf"^\s*\d+\s*:\s*C\s[^\n;]*\n\s*:\s*{pr_ref}"
    found_at = [*re.finditer(pat, text, re.M), *re.finditer(via, text, re.M)]
    for m in sorted(found_at, key=lambda m: m.start(1)):
        idx = re.fullmatch(r"\s*(?:GP1\s*:\s*)?(\d+)\s*(?::.*)?", m.group(2))
        key = idx.group(1) if idx else m.group(1)
        at = m.start(1)
        uses.setdefault(key, []).append(
            (at, _active(text, at, _UF), _active(text, at, _UT), m.group(1))
        )  # fmt: skip
    out = []
    for key, found in uses.items():
        at, uf, ut, name = found[0]
        frames = {(u, t) for _, u, t, _ in found}
        reg = (registers or {}).get(int(key)) if key.isdigit() else None
        why = ""
        if not key.isdigit():
            why = "an indirect register index: its value is not known before it runs"
        elif reg is None:
            why = (
                "a position register: its value is in the controller (give the "
                "controller's POSREG.VA, or posreg: in a YAML file, with --frames)"
            )
        elif reg.kind == "uninitialized":
            why = "the register is uninitialized in the registers given"
        kind = "" if reg is None else reg.kind
        if not why and kind == "cartesian":
            if len(frames) > 1:
                why = "moves use it with different UFRAME_NUM/UTOOL_NUM"
            elif None in (uf, ut) or "" in (uf, ut):
                why = "UFRAME_NUM and UTOOL_NUM are not both set (to numbers) before it"
        config = None
        if not why and kind == "cartesian" and reg is not None:
            try:
                config = _fanuc_config(reg.config, 0, f"PR[{key}]", reg.config)
            except DataError:
                why = f"its CONFIG {reg.config!r} is not 'N|F U|D T|B, t1, t4, t6'"
        vals = reg.values if reg is not None else ()
        moves = _moves(text, name, [f[0] for f in found if f[0] in offsets], offsets,
                       (uf or "0", ut or "0"))  # fmt: skip
        if kind == "joint":  # joints: no frame
            uf = ut = "0"
            if any(u[0] is not None for u in moves):
                why = why or "a joint register moved to with an offset is not handled"
        pt = CartesianPoint(name, _line(text, at), ((at, at),), tuple(vals),
                            (3,) * len(vals), config, uf or "0", ut or "0", why_not=why,
                            register=kind if not why else "")  # fmt: skip
        out += offset_targets(text, pt, moves)
    return out


def _fanuc_moving_base(text: str, seg: str, found: list[int]) -> str:
    """Why a pose cannot be corrected for a fixed robot base: extended axes in its group
    (``E1 = .. mm``: an integrated rail or turntable carries the robot), or a
    coordinated move (``COORD``: the pose is relative to the leader group's moving
    frame) at one of the motion references ``found``; '' when neither."""
    if re.search(r"\bE\d+\s*=", seg):
        return ("extended axes (E1..) in its group: the robot base moves with them, not "
                "handled")  # fmt: skip
    for at in found:
        line = text[text.rfind("\n", 0, at) + 1 : text.find("\n", at) % (len(text) + 1)]
        if re.search(r"\bCOORD\b", line):
            return ("a coordinated move (COORD, line "
                    f"{_line(text, at)}) uses it: its pose is relative to the leader "
                    "group's moving frame, not handled")  # fmt: skip
    return ""


def _fanuc_not_pose(seg: str) -> str:
    """Why the group 1 text ``seg`` of a position holds no X..R pose to correct: not
    taught (``X = ********``), written in another representation (``RX = ..``: a
    position of another kind than the world XYZWPR one), or no value at all; '' when it
    holds one (a malformed one is refused by the reader)."""
    if re.search(r"\bX\s*=\s*\*", seg):
        return "not taught: its values are '*' (an uninitialised position)"
    if re.search(r"\bX\s*=", seg):
        return ""
    keys = re.findall(r"\b([A-Z]\w*)\s*=", seg)
    if keys:
        return (f"its values are written as {', '.join(keys[:6])}, not X, Y, Z, W, P, R "
                "or J1..: not handled")  # fmt: skip
    return "no position values in its group 1"


def _moves(
    text: str, name: str, found: list[int], offsets: dict, frames: tuple[str, str]
) -> list[tuple]:
    """The uses (offset, position, name) of ``name`` by the motion references at ``found``
    (:func:`._cartesian_base.offset_targets`), an offset whose condition names another
    frame than ``frames`` (UF, UT) unknown."""
    out = []
    for at in found:
        _, _, off, label, frame = offsets[at]
        own = frames[label.startswith("Tool")]
        if off is not None and frame and frame != own:
            kind = "UTOOL" if label.startswith("Tool") else "UFRAME"
            off = ("?", f"{label}: its condition's {kind}[{frame}] is not the target's "
                        f"frame {own}: not handled")  # fmt: skip
        out.append((off, at, f"{name} {label}"))
    return out


def _fanuc(text: str, values: dict | None = None) -> list[CartesianPoint]:
    pos = re.search(r"^/POS\b", text, re.M)
    offsets = motion_offsets(text, values)
    registers = _fanuc_registers(text, values, offsets)
    if pos is None:
        return registers
    by_index: dict[int, list[int]] = {}  # n -> the motion references to P[n]
    for a, u in offsets.items():
        if u[0] == "P" and u[1] is not None:
            by_index.setdefault(u[1], []).append(a)
    end = re.search(r"^/END\b", text[pos.end() :], re.M)
    stop = pos.end() + end.start() if end else len(text)
    out = []
    for rec in re.finditer(r"(P\[[^\]]*\])\s*\{(.*?)\};", text[pos.end() : stop], re.S):
        for g in re.finditer(r"GP([2-9])\s*:(.*?)(?=GP\d+\s*:|\Z)", rec.group(2), re.S):
            if re.search(r"\bX\s*=", g.group(2)):  # another robot's pose
                a = pos.end() + rec.start(2) + g.start()
                out.append(CartesianPoint(
                    f"{rec.group(1)} GP{g.group(1)}", _line(text, a), ((a, a),), (), (),
                    None, "", "", why_not=f"motion group {g.group(1)} (another robot): "
                    "only group 1 is corrected"))  # fmt: skip
        g1 = re.search(r"GP1\s*:(.*?)(?=GP\d+\s*:|\Z)", rec.group(2), re.S)
        if g1 is None or re.search(r"\bJ\d+\s*=", g1.group(1)):
            continue  # no group 1, or joints (the joint reader's)
        seg, at = g1.group(1), pos.end() + rec.start(2) + g1.start(1)
        name = rec.group(1)
        why = _fanuc_not_pose(seg)
        if why:
            at = pos.end() + rec.start(1)
            out.append(CartesianPoint(name, _line(text, at), ((at, at),), (), (), None,
                                      "", "", why_not=why))  # fmt: skip
            continue
        spans = []
        for key, unit in zip("XYZWPR", ("mm",) * 3 + ("deg",) * 3):
            m = re.search(rf"\b{key}\s*=(\s*{_NUM})\s*{unit}", seg)
            if m is None:
                raise DataError(
                    f"line {_line(text, pos.end() + rec.start(1))}: {name} has no "
                    f"'{key} = <number> {unit}'; "
                    "expected X, Y, Z [mm] and W, P, R [deg]."
                )
            spans.append((at + m.start(1), at + m.end(1)))
        frames = re.search(r"\bUF\s*:\s*(\d+)\s*,\s*UT\s*:\s*(\d+)", seg)
        cfg = re.search(r"\b(?:CONFIG|KONFIG)\s*:\s*'([^']*)'", seg)
        if frames is None or cfg is None:
            raise DataError(
                f"line {_line(text, at)}: {name} lacks 'UF : u, UT : t' or "
                "CONFIG : '...'; expected both in a Cartesian position."
            )
        config = _fanuc_config(text, at + cfg.start(), name, cfg.group(1))
        pt = _make(text, name, spans, config=config, frame=frames.group(1),
                   tool=frames.group(2),
                   config_spans=((at + cfg.start(1), at + cfg.end(1)),))  # fmt: skip
        n = re.match(r"P\[\s*(\d+)", name)
        found = by_index.get(int(n.group(1)), []) if n else []
        why = _fanuc_moving_base(text, seg, found)
        if why:
            out.append(replace(pt, why_not=why))
            continue
        out += offset_targets(
            text, pt, _moves(text, name, found, offsets, (pt.frame, pt.tool))
        )
    return registers + out


# ------------------------------------------------------------------ KRL
def _krl_fdat(text: str) -> dict[str, tuple[str, str, str]]:
    """FDAT name suffix -> (BASE_NO, TOOL_NO, IPO_FRAME)."""
    out = {}
    for m in re.finditer(r"\bDECL\s+FDAT\s+F(\w+)\s*=\s*\{([^{}]*)\}", text, re.I):
        body = m.group(2)
        b = re.search(r"\bBASE_NO\s+(\d+)", body)
        t = re.search(r"\bTOOL_NO\s+(\d+)", body)
        ipo = re.search(r"\bIPO_FRAME\s+#(\w+)", body)
        out[m.group(1).upper()] = (
            b.group(1) if b else "0",
            t.group(1) if t else "0",
            ipo.group(1).upper() if ipo else "BASE",
        )
    return out


def _krl_active(text: str, pos: int, which: str) -> str:
    """The BASE_DATA / TOOL_DATA number set last before ``pos`` (``$BASE =
    BASE_DATA[n]`` or ``BAS(#BASE, n)``), '0' for none."""
    pat = rf"\${which}\s*=\s*{which}_DATA\s*\[\s*(\d+)\s*\]|\bBAS\s*\(\s*#{which}\s*,\s*(\d+)"
    last = None
    for m in re.finditer(pat, text[:pos], re.I):
        last = m.group(1) or m.group(2)
    return last or "0"


# A KRL motion whose aggregate is a displacement from where the robot is.
_KRL_REL = re.compile(r"\b(S?(?:PTP|LIN|CIRC)_REL)\s*$", re.I)


def _krl_left(text: str, m: re.Match, body: str) -> CartesianPoint | None:
    """A target of a KRL motion that is no pose to correct, counted and left: the
    aggregate of a relative motion (``LIN_REL {Z -20}``: a displacement), or a partial
    one in a motion (``PTP {A1 45}``, ``LIN {Z 300}``: the components it leaves out are
    the robot's current ones); None for any other aggregate."""
    head = text[text.rfind("\n", 0, m.start()) + 1 : m.start()]
    if re.search(r"(BASE_DATA|TOOL_DATA|\$\w+)\s*(\[[^\]]*\])?\s*=\s*$", head, re.I):
        return None  # a frame of the controller
    rel = _KRL_REL.search(head)
    keys = {
        k.upper() for k in re.findall(rf"(?<![\w$])([XYZABC]|A[1-6])\s+{_NUM}", body)
    }
    if rel is None and (  # partial: in a motion only (a declaration must be whole)
        not keys
        or keys >= set("XYZABC")
        or not re.search(r"\bS?(?:PTP|LIN|CIRC)\s*$", head, re.I)
    ):
        return None
    axes = {f"A{i}" for i in range(1, 7)}
    if rel is None and (keys >= axes or not (keys & set("XYZ") or keys <= axes)):
        return None  # a full joint aggregate (the joint reader's), or no target
    why = (
        f"a relative motion ({rel.group(1).upper()}): its aggregate is a displacement "
        "from where the robot is, not a pose"
        if rel
        else "a partial aggregate: the components it leaves out are the robot's "
        "current ones"
    )
    at = m.start(1)
    decl = re.search(r"(\w+)\s*=\s*$", head)
    name = rel.group(1).upper() if rel else (decl.group(1) if decl else "POS")
    return CartesianPoint(name, _line(text, at),
                          ((at, at),), (), (), None, "", "", why_not=why)  # fmt: skip


_EXT_AXES = ("external axes set (a rail or turntable may carry the robot: its base "
             "would move with them): not handled")  # fmt: skip


_KRL_GEO = re.compile(r"^[ \t]*S?(?:PTP|LIN|CIRC)\b[^\n]*:[^\n]*$", re.I | re.M)


def _krl_geo(text: str, m: re.Match, name: str) -> str:
    """Why the aggregate ``m`` (named ``name``) is no pose to reach on its own: an
    operand of the geometric operator of a motion (``LIN XP1:{X 0,..,Z 50,..}``,
    ``LIN OFS:XP1``: the motion goes to the combination), else ''."""
    for g in _KRL_GEO.finditer(text):
        if g.start() <= m.start() < g.end() or re.search(
            rf"(?<![\w$]){re.escape(name)}(?!\w)", g.group(0)
        ):
            return ("an operand of the geometric operator ':' (line "
                    f"{_line(text, g.start())}): the motion goes to the combination, "
                    "not handled")  # fmt: skip
    return ""


def _krl_unseen(text: str) -> list[CartesianPoint]:
    """The targets motions go to by name whose value this file does not hold (``PTP
    XP1`` in a ``.src``: XP1 is in the ``.dat``; ``PTP XHOME``: in ``$config.dat``),
    counted and left once each."""
    out, seen = [], set()
    for m in re.finditer(r"^[ \t]*S?(?:PTP|LIN|CIRC)[ \t]+(\w+)(?:[ \t]*,[ \t]*(\w+))?",
                         text, re.I | re.M):  # fmt: skip
        for k in (1, 2):
            name = m.group(k)
            if not name or name.upper() in seen or re.match(r"C_\w+$", name, re.I):
                continue
            seen.add(name.upper())
            if re.search(rf"(?<![\w$]){re.escape(name)}\s*=\s*\{{", text, re.I):
                continue  # its aggregate is here
            at = m.start(k)
            out.append(CartesianPoint(
                name, _line(text, at), ((at, at),), (), (), None, "", "",
                why_not="its value is not in this file (compensate the .dat that "
                "declares it; a HOME in $config.dat; or set at run time)"))  # fmt: skip
    return out


def _krl(text: str) -> list[CartesianPoint]:
    fdat = _krl_fdat(text)
    out = _krl_unseen(text)
    for m in re.finditer(r"\{([^{}]*)\}", text):
        body, at = m.group(1), m.start(1)
        left = _krl_left(text, m, body)
        if left is not None:
            out.append(left)
            continue
        if not re.search(r"\bX\s+" + _NUM, body):
            continue
        spans = []
        for key in "XYZABC":
            k = re.search(rf"(?<![\w$]){key}\s+({_NUM})", body)
            if k is None:
                raise DataError(
                    f"line {_line(text, at)}: a Cartesian aggregate without {key}; "
                    "expected X, Y, Z [mm], A, B, C [deg]."
                )
            spans.append((at + k.start(1), at + k.end(1)))
        s = re.search(rf"(?<!\w)S\s+({_NUM})", body)
        t = re.search(rf"(?<!\w)T\s+({_NUM})", body)
        config = _krl_flags(s, t, text, at)
        head = text[text.rfind("\n", 0, m.start()) + 1 : m.start()]
        if re.search(
            r"(BASE_DATA|TOOL_DATA|\$\w+)\s*(\[[^\]]*\])?\s*=\s*$", head, re.I
        ):
            continue  # a frame of the controller, not a target
        decl = re.search(r"(\w+)\s*=\s*$", head)
        name = decl.group(1) if decl else "POS"
        active = (
            _krl_active(text, m.start(), "BASE"),
            _krl_active(text, m.start(), "TOOL"),
        )
        base, tool, ipo = fdat.get(name[1:].upper(), (*active, "BASE"))
        why = (
            ""
            if ipo == "BASE"
            else f"IPO_FRAME #{ipo} (an external TCP) is not handled"
        )
        why = why or _krl_geo(text, m, name)
        ext = re.findall(rf"(?<![\w$])E[1-6]\s+({_NUM})", body)
        if not why and any(float(v) != 0.0 for v in ext):
            why = _EXT_AXES
        cfg_spans: tuple[tuple[int, int], ...] = ()
        if s and t:
            cfg_spans = (
                (at + s.start(1), at + s.end(1)),
                (at + t.start(1), at + t.end(1)),
            )
        out.append(
            _make(text, name, spans, config=config, frame=base, tool=tool, why_not=why,
                  config_spans=cfg_spans)
        )  # fmt: skip
    return out


_READERS = {"fanuc-ls": _fanuc, "krl": _krl, "rapid": _rapid, "urscript": _urscript}


def read_cartesian(
    text: str, fmt: str, registers: dict | None = None
) -> list[CartesianPoint]:
    """The Cartesian targets of a program text (see the module docstring);
    ``registers``: FANUC position register values ({n: Register}).

    Raises
    ------
    DataError
        A malformed target (naming its line).
    """
    text = code_only(text, fmt)
    if fmt == "fanuc-ls":
        return _fanuc(text, registers)
    return _READERS[fmt](text)


def cartesian_numbers(fmt: str, T: Pose, old: tuple[float, ...]) -> Float:
    """A pose as the format's numbers, the angle set nearest the old one."""
    if fmt == "rapid":
        q = matrix_to_quat_wxyz(T[:3, :3])
        if np.dot(q, old[3:7]) < 0:
            q = -q
        return np.concatenate([T[:3, 3] * 1e3, q])
    if fmt == "urscript":
        r = so3_log(T[:3, :3])
        ang = np.linalg.norm(r)
        if ang > 1e-12:  # r and r - 2 pi r/|r| are the same turn: keep the old branch
            alt = r * (ang - 2 * np.pi) / ang
            if np.linalg.norm(alt - old[3:6]) < np.linalg.norm(r - old[3:6]):
                r = alt
        return np.concatenate([T[:3, 3], r])
    e = np.degrees(matrix_to_euler_zyx(T[:3, :3]))  # z, y, x
    e = e[::-1] if fmt == "fanuc-ls" else e
    e = old[3:6] + (e - np.asarray(old[3:6]) + 180.0) % 360.0 - 180.0
    return np.concatenate([T[:3, 3] * 1e3, e])


def _fmt(value: float, dec: int, old: str) -> str:
    s = f"{value:.{dec}f}"
    if float(s) == 0.0:
        s = f"{0.0:.{dec}f}"
    if old[:1].isspace():  # FANUC: keep the column, and a blank after '='
        s = s.rjust(len(old)) if len(s) < len(old) else " " + s
    return s


def _config_edits(
    fmt: str, pt: CartesianPoint, cfg: tuple
) -> list[tuple[int, int, str]]:
    if fmt == "fanuc-ls":
        a, b = pt.config_spans[0]
        return [(a, b, f"{cfg[0]} {cfg[1]} {cfg[2]}, {cfg[3]}, {cfg[4]}, {cfg[5]}")]
    return [(a, b, str(v)) for (a, b), v in zip(pt.config_spans, cfg)]


def cartesian_edits(
    text: str,
    fmt: str,
    points: list[CartesianPoint],
    poses: Pose,
    q_new: Float | None = None,
    *,
    decimals: int | None = None,
    configs: list[tuple | None] | None = None,
) -> list[tuple[int, int, str]]:
    """Text edits (start, end, new) writing ``poses`` (N, 4, 4) [m] into the targets,
    (URScript ``_q`` companions: ``q_new`` (N, n) [rad]; new configuration flags where
    ``configs`` has them); rows with NaN are kept."""
    edits = []
    for k, pt in enumerate(points):
        if (
            not pt.values
            or pt.register
            or pt.follows
            or not np.isfinite(poses[k]).all()
        ):
            continue  # a register's value is written to the register program
        new_cfg = None if configs is None else configs[k]
        if new_cfg is not None and pt.config_spans:
            edits += _config_edits(fmt, pt, new_cfg)
        nums = cartesian_numbers(fmt, poses[k], pt.values)
        for j, (a, b) in enumerate(pt.spans):
            dec = (
                decimals
                if decimals is not None
                else max(pt.decimals[j], _MIN_DECIMALS[fmt])
            )
            if fmt == "rapid" and j >= 3:
                dec = max(dec, 9)  # a unit quaternion to 1e-9
            old = text[a:b]
            new = _fmt(float(nums[j]), dec, old)
            if float(new) != float(_fmt(pt.values[j], dec, "")):
                edits.append((a, b, new))
        if q_new is not None and pt.q_spans and np.isfinite(q_new[k]).all():
            for j, (a, b) in enumerate(pt.q_spans[: q_new.shape[1]]):
                dec = max(_decimals(text[a:b]), _MIN_DECIMALS["urscript"])
                edits.append((a, b, _fmt(float(q_new[k, j]), dec, "")))
    return edits


def _krl_flags(
    s: re.Match | None, t: re.Match | None, text: str, at: int
) -> tuple | None:
    """An E6POS/POS's (S, T) as integers (None without them); a value that is no small
    whole number (1e400, -3, 2.5) is refused with its line."""
    if s is None or t is None:
        return None
    vals = (float(s.group(1)), float(t.group(1)))
    if not all(np.isfinite(v) and v == int(v) and 0 <= v < 1 << 16 for v in vals):
        raise DataError(f"line {_line(text, at)}: S {s.group(1)}, T {t.group(1)}: "
                        "expected whole numbers (status and turn bits).")  # fmt: skip
    return int(vals[0]), int(vals[1])
