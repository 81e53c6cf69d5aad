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

Units: mm and deg (URScript m and rad). A target is returned with its pose in its own
frame, the frame ids it names and its configuration as written; which frame an id means
is for the caller (:mod:`kinecal.workflows._compensate`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

import numpy as np

from kinecal.errors import DataError
from kinecal.geometry import (
    euler_zyx_to_matrix,
    make_transform,
    matrix_to_euler_zyx,
    matrix_to_quat_wxyz,
    quat_wxyz_to_matrix,
    so3_exp,
    so3_log,
)
from kinecal.typing import Float, Pose

__all__ = [
    "CartesianPoint",
    "cartesian_edits",
    "cartesian_numbers",
    "point_pose",
    "rapid_frames",
    "read_cartesian",
    "urscript_features",
]

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_MIN_DECIMALS = {"fanuc-ls": 3, "krl": 4, "rapid": 6, "urscript": 8}


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


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def _decimals(token: str) -> int:
    m = re.match(r"\s*[-+]?\d*\.?(\d*)", token)
    return len(m.group(1)) if m and "." in token else 0


def _make(text, name, spans, **kw) -> CartesianPoint:
    vals = tuple(float(text[a:b]) for a, b in spans)
    dec = tuple(_decimals(text[a:b]) for a, b in spans)
    return CartesianPoint(name, _line(text, spans[0][0]), tuple(spans), vals, dec, **kw)


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


def _active(text: str, pos: int, what: str) -> str | None:
    """The ``UFRAME_NUM`` / ``UTOOL_NUM`` set last before ``pos`` ('' for none, None for
    one set from a register or expression)."""
    last = ""
    for m in re.finditer(rf"^\s*\d+\s*:\s*{what}\s*=\s*([^;]*);", text[:pos], re.M):
        last = m.group(1).strip()
    return last if last == "" or last.isdigit() else None


def _fanuc_registers(text: str, registers: dict | None) -> list[CartesianPoint]:
    """The position registers ``PR[n]`` motion instructions move to, one target per
    register (at its first use), with the frames active at its uses; its value from
    ``registers`` ({n: :class:`kinecal.io._fanuc_va.Register`}, a controller's
    POSREG.VA), else counted and left."""
    uses: dict[str, list[tuple[int, str | None, str | None, str]]] = {}
    pat = r"^\s*\d+\s*:\s*[JLCA]\s+(PR\[((?:[^\[\]]|\[[^\]]*\])*)\])"
    for m in re.finditer(pat, text, re.M):
        idx = re.fullmatch(r"\s*(?:GP1\s*:\s*)?(\d+)\s*(?::.*)?", m.group(2))
        key = idx.group(1) if idx else m.group(1)
        at = m.start(1)
        uses.setdefault(key, []).append(
            (at, _active(text, at, "UFRAME_NUM"), _active(text, at, "UTOOL_NUM"),
             m.group(1))
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
        if not why and kind == "cartesian":
            try:
                config = _fanuc_config(reg.config, 0, f"PR[{key}]", reg.config)
            except DataError:
                why = f"its CONFIG {reg.config!r} is not 'N|F U|D T|B, t1, t4, t6'"
        vals = reg.values if reg is not None else ()
        if kind == "joint":  # joints: no frame
            uf = ut = "0"
        out.append(
            CartesianPoint(name, _line(text, at), ((at, at),), tuple(vals), (3,) * len(vals),
                           config, uf or "0", ut or "0", why_not=why,
                           register=kind if not why else "")
        )  # fmt: skip
    return out


def _fanuc(text: str, registers: dict | None = None) -> list[CartesianPoint]:
    pos = re.search(r"^/POS\b", text, re.M)
    registers = _fanuc_registers(text, registers)
    if pos is None:
        return registers
    end = re.search(r"^/END\b", text[pos.end() :], re.M)
    stop = pos.end() + end.start() if end else len(text)
    out = []
    for rec in re.finditer(r"(P\[[^\]]*\])\s*\{(.*?)\};", text[pos.end() : stop], re.S):
        g1 = re.search(r"GP1\s*:(.*?)(?=GP\d+\s*:|\Z)", rec.group(2), re.S)
        if g1 is None or not re.search(r"\bX\s*=", g1.group(1)):
            continue
        seg, at = g1.group(1), pos.end() + rec.start(2) + g1.start(1)
        name = rec.group(1)
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
        cfg = re.search(r"\bCONFIG\s*:\s*'([^']*)'", seg)
        if frames is None or cfg is None:
            raise DataError(
                f"line {_line(text, at)}: {name} lacks 'UF : u, UT : t' or "
                "CONFIG : '...'; expected both in a Cartesian position."
            )
        config = _fanuc_config(text, at + cfg.start(), name, cfg.group(1))
        out.append(
            _make(text, name, spans, config=config, frame=frames.group(1),
                  tool=frames.group(2),
                  config_spans=((at + cfg.start(1), at + cfg.end(1)),))
        )  # fmt: skip
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


def _krl(text: str) -> list[CartesianPoint]:
    fdat = _krl_fdat(text)
    out = []
    for m in re.finditer(r"\{([^{}]*)\}", text):
        body, at = m.group(1), m.start(1)
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
        config = (int(float(s.group(1))), int(float(t.group(1)))) if s and t else None
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


# ------------------------------------------------------------------ RAPID
def _bracket_list(text: str, start: int) -> list[tuple[int, int]]:
    """Spans of the numbers in the '[...]' list opening at ``start``."""
    close = text.find("]", start)
    return [
        (start + 1 + m.start(), start + 1 + m.end())
        for m in re.finditer(_NUM, text[start + 1 : close])
    ]


def _rapid_uses(text: str) -> dict[str, set[tuple[str, str]]]:
    """robtarget name ('' for an inline one) -> {(tool, wobj)} of the move
    instructions that use it."""
    uses: dict[str, set[tuple[str, str]]] = {}
    for m in re.finditer(r"\b(Move(?:L|J|C|LDO|JDO))\b([^;]*);", text, re.I):
        # Commas inside [..] (an inline target) or (..) (Offs(p10, 0, 0, 50)) do not
        # separate arguments.
        args = [a.strip() for a in re.split(r",(?![^\[(]*[\])])", m.group(2))]
        n_targets = 2 if m.group(1).upper() == "MOVEC" else 1
        if len(args) < n_targets + 3:
            continue
        tool = re.match(r"\s*(\w+)", args[n_targets + 2])
        w = re.search(r"\\WObj\s*:=\s*(\w+)", m.group(2), re.I)
        pair = (tool.group(1) if tool else "tool0", w.group(1) if w else "wobj0")
        for a in args[:n_targets]:
            name = re.match(r"(\w+)", a)
            uses.setdefault(name.group(1) if name else "", set()).add(pair)
    return uses


def _rapid_pose(text: str, at: int) -> tuple[Pose, int]:
    """The pose ``[[x, y, z], [q1..q4]]`` whose first '[' is the first after ``at``, and
    the end of its quaternion list."""
    t_at = text.find("[", text.find("[", at) + 1)
    trans = _bracket_list(text, t_at)
    q_at = text.find("[", text.find("]", t_at) + 1)
    quat = _bracket_list(text, q_at)
    if len(trans) != 3 or len(quat) != 4:
        raise DataError(
            f"line {_line(text, at)}: expected a pose [[x, y, z], [q1, q2, q3, q4]]."
        )
    v = [float(text[a:b]) for a, b in trans + quat]
    return point_pose("rapid", tuple(v)), text.find("]", q_at)


def rapid_frames(text: str) -> tuple[dict[str, Pose | str], dict[str, Pose | str]]:
    """tooldata and wobjdata of a RAPID text: ({tool name: the tool in the flange frame},
    {wobj name: the object frame in the world frame}) (4, 4) [m], or why it cannot be
    used (str)."""
    tools: dict[str, Pose | str] = {}
    wobjs: dict[str, Pose | str] = {}
    pat = r"\b(tooldata|wobjdata)\s+(\w+)\s*:=\s*\[\s*(TRUE|FALSE)\s*,"
    for m in re.finditer(pat, text, re.I):
        kind, name, hold = m.group(1).lower(), m.group(2), m.group(3).upper()
        if kind == "tooldata":
            T, _ = _rapid_pose(text, m.end())
            tools[name] = T if hold == "TRUE" else "a stationary tool (robhold FALSE)"
            continue
        head = re.match(
            r"\s*(TRUE|FALSE)\s*,\s*\"([^\"]*)\"\s*,", text[m.end() :], re.I
        )
        if head is None:
            raise DataError(f"line {_line(text, m.start())}: wobjdata {name}: expected "
                            "[robhold, ufprog, \"ufmec\", [uframe], [oframe]].")  # fmt: skip
        uf, end = _rapid_pose(text, m.end() + head.end())
        of, _ = _rapid_pose(text, end + 1)
        why = "held by the robot (robhold TRUE)" if hold == "TRUE" else ""
        why = why or ("moved by a mechanical unit" if head.group(2) else "")
        wobjs[name] = why or uf @ of
    return tools, wobjs


def _rapid(text: str) -> list[CartesianPoint]:
    uses = _rapid_uses(text)
    out = []
    decl = r"\brobtarget\s+(\w+)\s*:=\s*\[|\b(Move(?:L|J))\s+\["
    for m in re.finditer(decl, text, re.I):
        open_at = m.end() - 1
        trans = _bracket_list(text, text.find("[", open_at + 1))
        q_at = text.find("[", text.find("]", open_at + 1) + 1)
        quat = _bracket_list(text, q_at)
        conf = _bracket_list(text, text.find("[", text.find("]", q_at) + 1))
        if len(trans) != 3 or len(quat) != 4 or len(conf) != 4:
            raise DataError(
                f"line {_line(text, m.start())}: robtarget {m.group(1) or m.group(2)}: "
                "expected [[x, y, z], [q1, q2, q3, q4], [cf1, cf4, cf6, cfx], [...]]."
            )
        config = tuple(int(float(text[a:b])) for a, b in conf)
        name = m.group(1) or m.group(2)
        if m.group(2):  # inline: the instruction's own tool and wobj
            rest = text[m.start() : text.find(";", m.start())]
            used = _rapid_uses(rest + ";").get("", {("tool0", "wobj0")})
        else:
            used = uses.get(name, set())
        why = ""
        if not used:
            why = "no move instruction uses it (its tool and wobj are unknown)"
        elif len(used) > 1:
            why = "moves use it with different tools or wobjs"
        tool, wobj = next(iter(used)) if len(used) == 1 else ("", "")
        out.append(
            _make(text, name, trans + quat, config=config, frame=wobj, tool=tool,
                  config_spans=tuple(conf),
                  why_not=why)
        )  # fmt: skip
    return out


# ------------------------------------------------------------------ URScript
_ID = r"[A-Za-z_]\w*"


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


def _ur_target(text: str, a: int, b: int) -> tuple[str, str, int] | None:
    """A move's target expression ``text[a:b]`` -> (frame, 'p' or a variable name, the
    index of the pose literal's '[' or of the name); None: not a plain Cartesian
    target (a joint list, an expression)."""
    arg = text[a:b]
    call = re.match(r"(get_inverse_kin|pose_trans)\s*\(", arg)
    if call and _close(text, a + call.end() - 1) == b:
        inner = _args(text, a + call.end() - 1)
        if call.group(1) == "get_inverse_kin":
            return _ur_target(text, *inner[0])
        feat = re.fullmatch(_ID, text[inner[0][0] : inner[0][1]])
        if len(inner) != 2 or feat is None:
            return None
        got = _ur_target(text, *inner[1])
        return None if got is None or got[0] else (feat.group(0), got[1], got[2])
    if arg.startswith("p[") and _close(text, a + 1) == b:
        return "", "p", a + 1
    if re.fullmatch(_ID, arg):
        return "", arg, a
    return None


def _ur_tcps(text: str) -> list[tuple[int, str]]:
    """(position, TCP pose text 'p[...]', or '?<expression>' when not a literal)."""
    out = []
    for m in re.finditer(r"\bset_tcp\s*\(", text):
        args = _args(text, m.end() - 1)
        arg = text[args[0][0] : args[0][1]] if args else ""
        lit = arg.startswith("p[") and _close(text, args[0][0] + 1) == args[0][1]
        out.append((m.start(), arg if lit else "?" + arg))
    return out


def _ur_assignments(text: str) -> dict[str, list[tuple[int, int]]]:
    """Variable -> [(start of its assignment, index of its '[' or -1: not a pose
    literal)], for every ``[global|local] name = ...``."""
    out: dict[str, list[tuple[int, int]]] = {}
    pat = rf"^[ \t]*(?:(?:global|local)\s+)?({_ID})\s*=(?!=)\s*"
    for m in re.finditer(pat, text, re.M):
        lit = text.startswith("p[", m.end())
        out.setdefault(m.group(1), []).append((m.start(1), m.end() + 1 if lit else -1))
    return out


def urscript_features(text: str) -> dict[str, Pose | str]:
    """Variables used as the frame of ``pose_trans(FEATURE, target)`` in moves: their
    pose in the base frame (4, 4) [m] where the script assigns one literal pose, else
    why it cannot be used."""
    assigned = _ur_assignments(text)
    out: dict[str, Pose | str] = {}
    for frame in {u[0] for u in _ur_uses(text)[0] if u[0]}:
        got = assigned.get(frame, [])
        if not got:
            continue  # not in the script: --uframe NAME=... may give it
        if len(got) > 1 or got[0][1] < 0:
            out[frame] = "assigned more than once or from an expression in the script"
            continue
        spans = _bracket_list(text, got[0][1])
        if len(spans) != 6:
            out[frame] = "not a pose p[x, y, z, rx, ry, rz]"
            continue
        out[frame] = point_pose("urscript", tuple(float(text[a:b]) for a, b in spans))
    return out


def _ur_uses(text: str) -> tuple[list[tuple[str, str, int, int]], dict[str, int]]:
    """The Cartesian targets of move instructions: [(frame, 'p' or variable, index of
    the literal or name, position of the move)], and {variable: position} of variables
    a move uses otherwise (in an expression)."""
    uses, other = [], {}
    for m in re.finditer(r"\b(movej|movel|movep|movec|servoj)\s*\(", text):
        args = _args(text, m.end() - 1)
        n = 2 if m.group(1) == "movec" else 1
        for a, b in args[:n]:
            got = _ur_target(text, a, b)
            if got is not None:
                uses.append((*got, m.start()))
                continue
            for v in re.finditer(_ID, text[a:b]):
                other.setdefault(v.group(0), a + v.start())
    return uses, other


def _urscript(text: str) -> list[CartesianPoint]:
    tcps = _ur_tcps(text)

    def tcp_at(pos: int) -> str:
        before = [t for at, t in tcps if at < pos]
        return before[-1] if before else (tcps[0][1] if tcps else "")

    uses, other = _ur_uses(text)
    assigned = _ur_assignments(text)
    features = {u[0] for u in uses if u[0]}
    out = []
    for frame, what, at, pos in uses:  # inline poses
        if what != "p":
            continue
        spans = _bracket_list(text, at)
        if len(spans) == 6:
            out.append(_make(text, text[pos:text.find("(", pos)], spans, config=None,
                             frame=frame, tool=tcp_at(pos)))  # fmt: skip
    for name, sites in assigned.items():
        lits = [(a, b) for a, b in sites if b >= 0]
        if not lits or name in features:
            continue
        used = {(u[0], tcp_at(u[3])) for u in uses if u[1] == name}
        polyscope = re.fullmatch(r"\w+_p", name) and re.search(
            rf"^[ \t]*global\s+{name}\s*=", text, re.M
        )
        if not used and not polyscope:
            continue  # a pose no move goes to: not a target
        qm = (
            re.search(rf"\bglobal\s+{name[:-2]}_q\s*=\s*\[", text)
            if polyscope
            else None
        )
        q_spans = _bracket_list(text, qm.end() - 1) if qm else []
        q_vals = tuple(float(text[a:b]) for a, b in q_spans)
        why = ""
        if name in other:
            why = (f"a move uses it in an expression (line {_line(text, other[name])}): "
                   "one correction cannot serve both")  # fmt: skip
        elif len(used) > 1:
            why = "moves use it with different features or TCPs"
        elif len(lits) < len(sites):
            why = "it is also assigned from an expression: its value is not known"
        frame, tool = next(iter(used)) if len(used) == 1 else ("", tcp_at(lits[0][0]))
        for _, b in lits:
            spans = _bracket_list(text, b)
            if len(spans) != 6:  # p[x, 0.1, ...]: not six numbers
                out.append(CartesianPoint(name, _line(text, b), ((b, b),), (), (), None,
                                          frame, tool, why_not="its pose is not six "
                                          "numbers p[x, y, z, rx, ry, rz]"))  # fmt: skip
                continue
            out.append(_make(text, name, spans, config=None, frame=frame,
                             tool=tool, q_spans=tuple(q_spans), q_values=q_vals,
                             why_not=why))  # fmt: skip
    for k, pt in enumerate(out):
        if pt.tool.startswith("?") and not pt.why_not:
            out[k] = replace(pt, why_not=f"set_tcp({pt.tool[1:]}): the TCP is not a pose "
                                         "literal")  # fmt: skip
    return sorted(out, key=lambda c: c.spans[0][0])


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
    if fmt == "fanuc-ls":
        return _fanuc(text, registers)
    return _READERS[fmt](text)


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
        if not pt.values or pt.register or not np.isfinite(poses[k]).all():
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
