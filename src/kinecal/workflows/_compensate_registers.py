"""FANUC position registers in ``kinecal compensate PROGRAM.LS --registers POSREG.VA``
(issue 34): the registers the program moves to, corrected as its own targets are.

Each register a motion instruction of the program goes to (``J PR[3] ...``) is read from
the controller's ``POSREG.VA`` (:mod:`kinecal.io._fanuc_registers`): a joint register is
corrected as a joint target; a Cartesian one in the user and tool frame the program
selected before the motion (``UFRAME_NUM``, ``UTOOL_NUM``), with its configuration, as a
Cartesian target. They are solved as the positions of a program of their own (the same
path as the program's positions: one solver, one count), and the corrected values go back
as a TP program that sets them (``PR[i,j]=value``).
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.compensation import CompensationResult
from kinecal.errors import DataError

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class RegisterRun:
    """The registers' part of a program run: per corrected or unreachable register a
    row of ``result`` (named by ``where``), the registers left and why (``left``), the
    TP program that sets the corrected values (``text``) and what was said."""

    result: CompensationResult | None
    where: tuple[str, ...]
    left: tuple[str, ...]
    text: str
    messages: tuple[str, ...]


def _entry(reg: Any, uf: str, ut: str) -> list[str]:
    """The register as a position record of a TP program's ``/POS`` section."""
    head = [f"P[{reg.index}]{{", "   GP1:"]
    if reg.joints is not None:
        vals = [f"J{j}= {v:.6f} deg" for j, v in enumerate(reg.joints, 1)]
        return [*head, "\tUF : 0, UT : 0,", "\t" + ",\t".join(vals), "};"]
    x, y, z, w, p, r = reg.cartesian
    return [
        *head,
        f"\tUF : {uf}, UT : {ut},\t\tCONFIG : '{reg.config}',",
        f"\tX = {x:.6f}  mm,\tY = {y:.6f}  mm,\tZ = {z:.6f}  mm,",
        f"\tW = {w:.6f} deg,\tP = {p:.6f} deg,\tR = {r:.6f} deg",
        "};",
    ]


def _chosen(
    regs: dict[int, Any], motions: list[Any], source: str
) -> tuple[list[tuple[Any, str, str]], list[str]]:
    """The registers to correct (with their frames) and those left, with why."""
    uses: dict[int, list[Any]] = {}
    for m in motions:
        if m.index is not None:
            uses.setdefault(m.index, []).append(m)
    todo, left = [], []
    for idx, ms in uses.items():
        reg = regs.get(idx)
        where = f"PR[{idx}] (program line {ms[0].line})"
        if reg is None:
            left.append(f"{where}: not initialised in {source}")
            continue
        if reg.joints is not None:
            todo.append((reg, "0", "0"))
            continue
        frames = sorted({(m.uframe, m.utool) for m in ms}, key=str)
        unset = next((m for m in ms if m.uframe is None or m.utool is None), None)
        if unset is not None:
            left.append(
                f"{where}: the program selects no UFRAME_NUM and UTOOL_NUM (as numbers) "
                f"before line {unset.line}, and a register holds no frame"
            )
        elif len(frames) > 1:
            seen = ", ".join(f"UF {u} UT {t}" for u, t in frames)
            left.append(f"{where}: moved to in different frames ({seen})")
        else:
            todo.append((reg, *frames[0]))
    return todo, left


def compensate_registers(
    cal: Any,
    prog: Any,
    registers: str | Path,
    *,
    uframes: dict[str, np.ndarray],
    utools: dict[str, np.ndarray],
    tol_mm: float,
    payload_kg: float | None,
    name: str,
    solve: Callable[..., Any],
) -> RegisterRun:
    """Correct the position registers ``prog`` moves to (see the module docstring);
    ``name``: of the TP program written; ``solve``: the program compensation
    (:func:`~kinecal.workflows.compensate_program`) the stand-in program goes through."""
    from kinecal.io._fanuc_registers import (
        read_position_registers,
        register_motions,
        registers_program,
    )

    source = str(registers)
    regs = read_position_registers(registers)
    todo, left = _chosen(regs, register_motions(prog.text), source)
    if not todo:
        return RegisterRun(None, (), tuple(left), "", ())
    mn = [
        f"{i:4d}:J P[{reg.index}] 100% FINE ;" for i, (reg, _, _) in enumerate(todo, 1)
    ]
    pos = [ln for reg, uf, ut in todo for ln in _entry(reg, uf, ut)]
    text = "\r\n".join(["/PROG  KC_PR", "/MN", *mn, "/POS", *pos, "/END", ""])
    said: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "registers.ls"
        path.write_text(text)
        tmp_name = str(path)

        def named(
            line: str,
        ) -> str:  # the registers by their numbers, not the stand-in's
            line = re.sub(r"line \d+ \((P\[\d+\])(, Cartesian)?\)", r"P\1", line)
            return line.replace(tmp_name, source).replace("PP[", "PR[")

        try:
            run = solve(
                cal, path, "fanuc-ls", tol_mm=tol_mm, payload_kg=payload_kg,
                decimals=4, uframes=uframes, utools=utools, say=said.append,
            )  # fmt: skip
        except DataError as exc:  # named by the registers, not the stand-in program
            raise DataError(named(str(exc))) from None

    values, notes = [], []
    for reg, _, _ in todo:
        rec = re.search(rf"P\[{reg.index}\]\{{(.*?)\}};", run.text, re.S)
        assert rec is not None  # the stand-in's own record
        body = rec.group(1)
        if reg.joints is not None:
            vals = tuple(float(v) for v in re.findall(rf"J\d+\s*=\s*({_NUM})", body))
        else:
            vals = tuple(
                float(re.search(rf"\b{k}\s*=\s*({_NUM})", body).group(1))  # type: ignore[union-attr]
                for k in "XYZWPR"
            )
            cfg = re.search(r"CONFIG : '([^']*)'", body)
            if cfg is not None and cfg.group(1) != reg.config:
                notes.append(
                    f"PR[{reg.index}] configuration now {cfg.group(1)} (was "
                    f"{reg.config}): set it on the pendant"
                )
        old = reg.joints if reg.joints is not None else reg.cartesian
        if not np.allclose(vals, old, atol=0.0, rtol=0.0):
            values.append((reg, vals))
    where = tuple(named(w) for w in run.where)
    # The rows are the stand-in's: its joint positions first, then its Cartesian ones.
    rows = [int(re.search(r"\[(\d+)\]", w).group(1)) for w in where]  # type: ignore[union-attr]
    ok = {i for i, s in zip(rows, run.result.status, strict=True) if s == "ok"}
    values = [(reg, v) for reg, v in values if reg.index in ok]
    out = registers_program(name, source, values, notes, 4) if values else ""
    return RegisterRun(
        run.result, where, tuple(left), out, tuple(named(m) for m in said)
    )
