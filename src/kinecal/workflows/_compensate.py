"""The compensation workflows of ``kinecal compensate``: corrected controller angles
for the targets of a CSV file, or a corrected robot program (its joint targets, and its
Cartesian targets in their user and tool frames; the rest of the program byte for byte
but for the comment line that marks it compensated: :mod:`._provenance`).
"""

from __future__ import annotations

import numbers
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.compensation import CompensationResult
from kinecal.errors import DataError
from kinecal.io import CompensationTargets
from kinecal.measurement import CalibratedModel
from kinecal.measurement._calibrated import map_labels
from kinecal.workflows._args import need, need_model

__all__ = [
    "ProgramCompensation",
    "TargetCompensation",
    "compensate_program",
    "compensate_targets",
]

# Positions beyond 1 km from the instrument's origin are typing errors, not data (and
# their squares overflow in the solvers).
MAX_POSITION_MM = 1e6
# err_mm and status stay the last two columns, as before issue 23.
DIAG_HEADER = ["rot_err_deg", "dq_max_deg", "cond", "limit_joint", "err_mm", "status"]

Say = Callable[[str], None]


def _stderr(line: str) -> None:
    """Nowhere: the lines are kept in the result's ``messages``."""


@dataclass(frozen=True)
class _Compensation:
    result: CompensationResult
    where: tuple[str, ...]  # how each row is named in messages
    messages: tuple[str, ...]  # what the work said on the way (warnings, counts)

    def unreachable(self) -> list[int]:
        """The rows not corrected for another reason than being left as written."""
        return [i for i, s in enumerate(self.result.status) if s not in ("ok", "left")]

    def motion_warnings(self, path: str, warn_dq_deg: float = 1.0) -> list[str]:
        """Warnings for corrections that move a joint by more than ``warn_dq_deg``, and
        for singular poses solved with the least joint motion (the first 50 each)."""
        res, where = self.result, self.where
        dq = np.degrees(np.abs(res.joint_change))
        moved = np.flatnonzero((res.status == "ok") & (dq.max(axis=1) > warn_dq_deg))
        out = []
        for i in moved[:50]:
            j = int(np.argmax(dq[i]))
            out.append(
                f"warning   {path}: {where[i]}: the correction moves J{j + 1} by "
                f"{dq[i, j]:.3f} deg (more than --warn-dq-deg {warn_dq_deg:g})"
            )
        relaxed = (
            np.zeros(0, int) if res.relaxed is None else np.flatnonzero(res.relaxed)
        )
        for i in relaxed[:50]:
            out.append(
                f"warning   {path}: {where[i]}: next to a singular pose: position met, "
                f"the tool turned {np.degrees(res.rotation_error[i]):.4f} deg from the "
                "wanted orientation to keep the joints still (largest joint change "
                f"{dq[i].max():.4f} deg)"
            )
        return out

    def unreachable_lines(self, path: str) -> list[str]:
        """The unreachable or out-of-limit rows, one line each (the first 50)."""
        res, bad = self.result, self.unreachable()
        out = []
        for i in bad[:50]:
            joint = ""
            if res.limit_joint[i] >= 0:
                joint = f" (J{res.limit_joint[i] + 1} beyond its limit)"
            out.append(
                f"{path}: {self.where[i]}: {res.status[i]}{joint}: predicted error "
                f"{res.error[i] * 1e3:.4f} mm"
            )
        if len(bad) > 50:
            out.append(f"... and {len(bad) - 50} more rows")
        return out

    def summary(self) -> dict[str, Any]:
        """The figures of ``kinecal compensate --json`` (without ``out``)."""
        res = self.result
        ok = res.status == "ok"
        return {
            "n": len(res.status),
            "ok": int(ok.sum()),
            "unreachable": len(self.unreachable()),
            "left": int((res.status == "left").sum()),
            "max_err_mm": float(res.error[ok].max() * 1e3) if ok.any() else None,
            "max_dq_deg": float(dq_deg(res)[ok].max()) if ok.any() else None,
        }


@dataclass(frozen=True)
class TargetCompensation(_Compensation):
    """What :func:`compensate_targets` found: ``result`` per row of ``targets``."""

    targets: CompensationTargets = field(repr=False)

    def csv_text(self) -> str:
        """The corrected CSV: the same rows with corrected joints, the program's
        joints in ``j*_program`` columns and the diagnostic columns."""
        from kinecal.io import Column, table_csv

        res, tg = self.result, self.targets
        to_file = {"deg": 180.0 / np.pi, "rad": 1.0, "mm": 1e3, "m": 1.0}
        new = {
            c: Column.numbers(res.q_ctrl[:, k] * to_file[c.rsplit("_", 1)[1]], "%.8f")
            for k, c in enumerate(tg.joint_columns)
        }
        cols = [(c, new.get(c) or Column.copy_of(c)) for c in tg.table.header]
        cols += [(f"{c}_program", Column.copy_of(c)) for c in tg.joint_columns]
        return table_csv(tg.table, cols + diagnostic_columns(res))


@dataclass(frozen=True)
class ProgramCompensation(_Compensation):
    """What :func:`compensate_program` found: ``result`` per joint target, then per
    Cartesian target; ``text`` the corrected program, ``report`` its per-target CSV,
    ``written_note`` the largest error of the joint targets as written."""

    text: str = field(repr=False)
    report: str = field(repr=False)
    written_note: str | None = None
    registers: dict = field(default_factory=dict, repr=False)  # FANUC {n: corrected}

    def register_outputs(self, out_path: str | Path) -> dict[str, str]:
        """FANUC: {path: text} of the TP program writing the corrected position
        registers (:func:`register_path`; none when no register was corrected)."""
        from kinecal.io._fanuc_va import register_program

        if not self.registers:
            return {}
        path, name = register_path(out_path)
        return {path: register_program(name, self.registers, Path(out_path).name)}


def register_path(out_path: str | Path) -> tuple[str, str]:
    """(path, program name) of the register program of a corrected FANUC program
    ``out_path``: ``<OUT>_PR.LS`` beside it (a TP name: letters, digits, '_')."""
    import re

    out = Path(out_path)
    name = re.sub(r"\W", "_", out.stem.upper())[:33] + "_PR"
    name = name if name[0].isalpha() else "P" + name[:35]
    return str(out.with_name(name + (".LS" if out.suffix.isupper() else ".ls"))), name


def compensate_targets(
    cal: CalibratedModel,
    targets: str | Path,
    *,
    tol_mm: float = 0.001,
    payload_kg: float | None = None,
    allow_out_of_limits: bool = False,
    say: Say | None = None,
) -> TargetCompensation:
    """Corrected controller angles for the targets of ``targets`` (CSV: x_mm, y_mm, z_mm
    in the user frame, optional qw..qz, the program's joints as seeds), as ``kinecal
    compensate TARGETS.csv`` finds them.

    A row is reachable when the model's predicted error is below ``tol_mm``;
    ``payload_kg`` the load (default: the calibration's). ``say`` gets each warning
    line as it is found (they are also in ``messages``).

    Returns
    -------
    TargetCompensation
        The result per row and the corrected CSV (``csv_text()``).

    Raises
    ------
    DataError
        A bad file, a set or marker not in the model, a payload the model cannot take.
    """
    from kinecal.compensation import compensate as run_compensation
    from kinecal.io import read_compensation_targets
    from kinecal.workflows._provenance import refuse_corrected
    from kinecal.workflows._seeds import check_seed_units

    need_model(cal)
    need(targets, (str, Path), "targets")
    lines: list[str] = []
    emit = _emitter(lines, say)
    scale = load_scale(cal, payload_kg)
    tg = read_compensation_targets(
        targets, cal.model.robot, allow_out_of_limits=allow_out_of_limits
    )
    refuse_corrected(str(targets), tg.table.header)  # CORRECTED.csv: not twice
    for d in tg.diagnostics:
        if d.severity == "warning":
            emit(f"warning   {d.message}")
    _warn_extrapolation(cal, tg.q_seed, tg.table.lines, str(targets), emit)
    check_positions(tg.p, tg.table.lines, str(targets), "x_mm, y_mm, z_mm")
    spec = cal.model.spec
    path = str(targets)
    set_index, marker_index = (
        map_labels(lab, idx, own, what, f"{path}: column '{what}'", noun="targets")
        for lab, idx, own, what in (
            (tg.set_labels, tg.set_index, spec.sets, "set"),
            (tg.marker_labels, tg.marker_index, spec.markers, "marker"),
        )
    )
    check_seed_units(cal, tg, set_index, marker_index, path)
    N = tg.p.shape[0]
    rows = _row_load_scale(cal, tg.payload_kg, payload_kg, path)
    res = run_compensation(
        cal,
        tg.p,
        tg.q_seed,
        R_target=tg.R,
        set_index=set_index,
        marker_index=marker_index,
        load_scale=rows if scale is None else np.full(N, scale),
        tol=tol_mm * 1e-3,
    )
    where = tuple(f"line {ln}" for ln in tg.table.lines)
    return TargetCompensation(res, where, tuple(lines), tg)


def compensate_program(
    cal: CalibratedModel,
    path: str | Path,
    fmt: str,
    *,
    tol_mm: float = 0.001,
    payload_kg: float | None = None,
    decimals: int | None = None,
    uframes: dict[str, np.ndarray] | None = None,
    utools: dict[str, np.ndarray] | None = None,
    registers: dict | None = None,
    say: Say | None = None,
) -> ProgramCompensation:
    """The corrected robot program ``path`` (``fmt``: fanuc-ls, urscript, rapid, krl),
    as ``kinecal compensate PROGRAM`` writes it.

    Each joint target is moved so that the real robot takes the flange pose the
    nominal robot has at the programmed joints; each Cartesian target (in its user and
    tool frames: ``uframes``, ``utools``, {id: pose (4, 4) [m]}) becomes the pose the
    nominal controller must be commanded for the real robot to reach it; FANUC
    ``registers`` ({n: :class:`kinecal.io._fanuc_va.Register`}, the controller's
    position registers) are corrected where the program moves to them
    (:meth:`ProgramCompensation.register_outputs`). ``decimals``:
    of the written joints (default: the file's). ``say`` gets each message line as it
    is found (they are also in ``messages``).

    Returns
    -------
    ProgramCompensation
        The corrected program, its per-target report and the result per target.
    """
    from kinecal.io import read_program, write_program, written_joints
    from kinecal.models import ModelInputs
    from kinecal.workflows import _provenance as provenance
    from kinecal.workflows._compensate_cartesian import (
        cartesian_run,
        settle_follows,
        written_errors,
    )

    lines: list[str] = []
    emit = _emitter(lines, say)
    scale = load_scale(cal, payload_kg)  # (a CalibratedModel: need_model)
    robot = cal.model.robot
    prog = read_program(path, fmt)
    provenance.refuse_compensated_program(str(path), prog.text, prog.format)
    q_prog, p_t, res_j, ls = _joint_part(cal, prog, scale, tol_mm)
    run = cartesian_run(
        cal, prog, q_prog, uframes or {}, utools or {}, scale, tol_mm, decimals,
        registers,
    )  # fmt: skip
    _program_extrapolation(cal, prog, q_prog, run, str(path), emit)
    keep = (res_j.status != "ok") if res_j is not None else np.zeros(0, bool)
    q_w_in = res_j.q_ctrl if res_j is not None else q_prog
    text = write_program(
        prog, q_w_in, robot, decimals=decimals, keep=keep, extra=run.edits
    )
    # The predicted error of what is written (the joints rounded to the file's decimals).
    q_w = written_joints(prog, text, robot)
    err_w = np.zeros(0)
    if q_w.shape[0]:
        out = cal.model.evaluate(
            cal.params, ModelInputs.make(q_w, load_scale=ls)
        ).p_user
        err_w = np.linalg.norm(out - p_t, axis=1)
    err_c, rot_c = written_errors(cal, run, text, prog.format, scale)
    settle_follows(run, err_c, rot_c, tol_mm)
    res = _joined(res_j, run, robot.n_joints)
    names = [pt.name for pt in prog.points] + [
        f"{pt.name}, Cartesian" for pt in run.points
    ]
    lines_ = [pt.line for pt in prog.points] + [pt.line for pt in run.points]
    q_w_all = np.vstack([q_w, np.nan_to_num(run.q_new)])
    err_all = np.concatenate([err_w, err_c])
    for pt in prog.points:
        if pt.why_not:
            emit(f"{path}: line {pt.line} ({pt.name}): left as written: {pt.why_not}")
    _echo_cartesian(str(path), run, err_c, rot_c, emit)
    report = _report_text(res, names, lines_, q_w_all, err_all, robot)
    n_j = int((~keep).sum())
    n_left = sum(bool(pt.why_not) for pt in prog.points)
    note = None
    if keep.size:
        note = (
            f"{path}: {n_j} joint targets corrected"
            f"{f', {n_left} left as written' if n_left else ''}; largest error as "
            f"written {err_w[~keep].max() * 1e3 if n_j else 0:.4f} mm "
            "(the joints rounded to the file's decimals)."
        )
    where = tuple(f"line {ln} ({nm})" for ln, nm in zip(lines_, names))
    text = provenance.mark_compensated(text, prog.format)  # after every read-back
    return ProgramCompensation(
        res, where, tuple(lines), text, report, note, run.registers_new
    )


def _emitter(lines: list[str], say: Say | None) -> Say:
    def emit(line: str) -> None:
        lines.append(line)
        (say or _stderr)(line)

    return emit


def _row_load_scale(
    cal: CalibratedModel, column: Any, option: float | None, path: str
) -> Any:
    """The load scale per row of a ``payload_kg`` column (None without one)."""
    if column is None:
        return None
    if option is not None:
        raise DataError(
            f"{path}: column 'payload_kg' and --payload-kg both give the payload; "
            "expected one of them."
        )
    ref = cal.reference_payload_kg
    if ref is None:
        check_payload_scales(cal, f"{path}: column 'payload_kg'")
        return None
    return np.asarray(column, float) / ref


def load_scale(cal: CalibratedModel, payload_kg: float | None) -> float | None:
    """The load scale of ``payload_kg`` (None: the calibration's) for the model
    ``cal`` (ConfigError for anything else)."""
    need_model(cal)
    if payload_kg is None:
        return None
    if isinstance(payload_kg, bool) or not isinstance(payload_kg, numbers.Real):
        raise DataError(f"--payload-kg: expected a number [kg]; got {payload_kg!r}.")
    if not payload_kg >= 0:
        raise DataError(f"--payload-kg must be >= 0; got {payload_kg}.")
    from kinecal.io._model_bounds import payload_limit

    hi, also = payload_limit(cal.model.robot)
    if payload_kg > hi:
        raise DataError(
            f"--payload-kg {payload_kg:g}: expected at most {hi:g} kg{also}: a unit "
            "mistake (g, lb)?"
        )
    ref = cal.reference_payload_kg
    if ref is None:
        check_payload_scales(cal, f"--payload-kg {payload_kg:g}")
        return None
    return payload_kg / ref


def check_payload_scales(cal: CalibratedModel, what: str) -> None:
    """Refuse a payload (``what``: the option or column giving it) for a model with
    payload compliance but no reference payload: that compliance is per unit of the
    calibration's unknown load (DataError). A model with a reference payload, or
    without payload compliance (nothing to scale), passes."""
    if cal.reference_payload_kg is None and cal.model.spec.load:
        raise DataError(
            f"{what}: the model has no reference payload (its payload compliance is per "
            "unit of the calibration's unknown load, so a payload cannot scale it); "
            "expected no payload with this model, or a model calibrated on data with a "
            "payload_kg column."
        )


def check_positions(p_m: Any, lines: Any, path: str, columns: str) -> None:
    """Refuse positions (N, 3) [m] farther than :data:`MAX_POSITION_MM` from the
    origin, naming the file line."""
    far = np.flatnonzero(np.abs(np.asarray(p_m)).max(axis=1) * 1e3 > MAX_POSITION_MM)
    if far.size:
        i = int(far[0])
        v = np.asarray(p_m)[i] * 1e3
        raise DataError(
            f"{path}: line {lines[i]}, columns {columns}: ({v[0]:.6g}, {v[1]:.6g}, "
            f"{v[2]:.6g}) mm; expected positions within {MAX_POSITION_MM:.0e} mm of the "
            "origin (a typing error?)."
        )


def dq_deg(res: CompensationResult) -> np.ndarray:
    """The largest joint change of each row [deg]."""
    return np.degrees(np.abs(res.joint_change)).max(axis=1)


def diagnostics(res: CompensationResult, i: int) -> list[str]:
    """The diagnostic columns of row i: every one numeric, the status last."""
    return [
        f"{np.degrees(res.rotation_error[i]):.6f}",
        f"{np.degrees(np.abs(res.q_ctrl[i] - res.q_program[i])).max():.6f}",  # dq_deg
        f"{res.cond[i]:.4g}",
        str(int(res.limit_joint[i]) + 1),  # 1-based; 0: none
        f"{res.error[i] * 1e3:.6f}",
        str(res.status[i]),
    ]


def diagnostic_columns(res: CompensationResult) -> list[tuple[str, Any]]:
    """The diagnostic columns of every row at once (as :func:`diagnostics` per row)."""
    from kinecal.io import Column

    values = (
        Column.numbers(np.degrees(res.rotation_error), "%.6f"),
        Column.numbers(dq_deg(res), "%.6f"),
        Column.numbers(res.cond, "%.4g"),
        Column.numbers(np.asarray(res.limit_joint) + 1, "%d"),  # 1-based; 0: none
        Column.numbers(res.error * 1e3, "%.6f"),
        Column.text([str(x) for x in res.status]),
    )
    return list(zip(DIAG_HEADER, values))


def _warn_extrapolation(
    cal: CalibratedModel, q: np.ndarray, rows: Any, source: str, emit: Say,
    labels: list[str] | None = None,
) -> None:  # fmt: skip
    """Targets outside the joint ranges the model was calibrated on (a warning)."""
    from kinecal.io import extrapolation

    found = extrapolation(cal, q, rows, source, what="targets", labels=labels)
    if found is not None and found.severity == "warning":
        emit(f"warning   {found.message}")


def _program_extrapolation(
    cal: CalibratedModel, prog: Any, q_prog: np.ndarray, run: Any, path: str, emit: Say
) -> None:
    """Joint and Cartesian targets outside the calibrated ranges, named by line."""
    # (an incremental move's joints are a displacement: not a pose to warn about)
    seeded = np.all(np.isfinite(run.q_seed), axis=1)
    q_all = np.vstack([q_prog, run.q_seed[seeded]])
    pts = [*prog.points, *(p for p, ok in zip(run.points, seeded) if ok)]
    rows = [
        i + 1 for i, pt in enumerate(pts) if i >= len(prog.points) or not pt.why_not
    ]
    names = [f"line {pts[r - 1].line} ({pts[r - 1].name})" for r in rows]
    _warn_extrapolation(cal, q_all[np.array(rows, int) - 1], rows, path, emit, names)


def _joint_part(
    cal: CalibratedModel, prog: Any, scale: float | None, tol_mm: float
) -> tuple[np.ndarray, np.ndarray, CompensationResult | None, np.ndarray | None]:
    """Compensate the joint targets of a program: (q_prog, p_t, res, ls)."""
    from kinecal.compensation import compensate as run_compensation
    from kinecal.compensation import program_targets
    from kinecal.io import program_joints

    q_prog = program_joints(prog, cal.model.robot)
    _refuse_wild(prog, q_prog, cal.model.robot)
    N = q_prog.shape[0]
    ls = None if scale is None else np.full(N, scale)
    if N == 0:
        return q_prog, np.zeros((0, 3)), None, ls
    p_t, R_t = program_targets(cal, q_prog)
    res = run_compensation(
        cal, p_t, q_prog, R_target=R_t, load_scale=ls, tol=tol_mm * 1e-3
    )
    left = np.array([bool(pt.why_not) for pt in prog.points])
    if left.any():  # kept as written (an incremental move's displacement)
        status = res.status.astype(object)
        status[left] = "left"
        res = replace(
            res, status=status.astype(str), q_ctrl=np.where(left[:, None], q_prog,
            res.q_ctrl), error=np.where(left, np.nan, res.error),
        )  # fmt: skip
    return q_prog, p_t, res, ls


def _refuse_wild(prog: Any, q: np.ndarray, robot: Any) -> None:
    """A joint target more than a turn (a stroke, at least 100 mm) beyond the robot's
    limits is no joint value (1e9 deg was wrapped and 'corrected' into another pose);
    one nearer them is solved and reported as 'joint_limit'."""
    lim = robot.limits
    far = np.where(robot.prismatic, np.maximum(lim[:, 1] - lim[:, 0], 0.1), 2 * np.pi)
    wild = (q < lim[:, 0] - far) | (q > lim[:, 1] + far) | ~np.isfinite(q)
    if not wild.any():
        return
    i, k = (int(x) for x in np.argwhere(wild)[0])
    pt = prog.points[i]
    rad = prog.format == "urscript"  # URScript: m and rad; the others mm and deg
    unit, f = (
        ("m" if rad else "mm", 1.0 if rad else 1e3)
        if robot.prismatic[k]
        else ("rad" if rad else "deg", 1.0 if rad else 180.0 / np.pi)
    )
    raise DataError(
        f"{prog.path}: line {pt.line} ({pt.name}): J{k + 1} = {pt.values[k]:.6g} {unit} "
        f"is not a joint value of {robot.name} (limits [{lim[k, 0] * f:.6g}, "
        f"{lim[k, 1] * f:.6g}] {unit}); expected a value within a turn of them."
    )


def _joined(res: CompensationResult | None, run: Any, n: int) -> CompensationResult:
    """The joint targets' result and the Cartesian targets' as one CompensationResult
    (Cartesian targets left as written: status 'left', NaN errors)."""
    Nc = len(run.points)
    err = np.full(Nc, np.nan)
    rot = np.full(Nc, np.nan)
    cond = np.full(Nc, np.nan)
    lim = np.full(Nc, -1)
    relaxed = np.zeros(Nc, bool)
    q_new = np.where(np.isfinite(run.q_new), run.q_new, run.q_seed)
    if run.res is not None:
        r = run.res
        err[run.rows], rot[run.rows], cond[run.rows] = r.error, r.rotation_error, r.cond
        lim[run.rows] = r.limit_joint
        relaxed[run.rows] = r.relaxed
    for k, (e, r_) in run.follow_err.items():  # RAPID offsets following a robtarget
        err[k], rot[k], cond[k] = e, r_, np.nan
    parts = [
        (np.nan_to_num(q_new), np.nan_to_num(run.q_seed), err, rot,
         np.asarray(run.status, str), lim, cond, relaxed)
    ]  # fmt: skip
    if res is not None:
        relax = np.zeros(len(res.status), bool) if res.relaxed is None else res.relaxed
        parts.insert(0, (res.q_ctrl, res.q_program, res.error, res.rotation_error,
                         res.status, res.limit_joint, res.cond, relax))  # fmt: skip
    cols = [np.concatenate(c) if c[0].ndim == 1 else np.vstack(c) for c in zip(*parts)]
    cols[0], cols[1] = (c.reshape(-1, n) for c in cols[:2])
    it = 0 if res is None else res.iterations
    q_ctrl, q_program, error, rot_err, status, limit_joint, cond, relaxed = cols
    return CompensationResult(
        q_ctrl, q_program, error, rot_err, status, limit_joint, cond, it, relaxed
    )


def _report_text(
    res: CompensationResult,
    names: Sequence[str],
    lines_: Sequence[int],
    q_w: np.ndarray,
    err_w: np.ndarray,
    robot: Any,
) -> str:
    head = ["point", "line", *(f"j{k + 1}_program" for k in range(robot.n_joints))]
    head += [f"j{k + 1}" for k in range(robot.n_joints)]
    out = [",".join([*head, "err_written_mm", *DIAG_HEADER])]
    deg = np.where(robot.prismatic, 1e3, 180.0 / np.pi)
    for i, name in enumerate(names):
        vals = [f"{v:.8f}" for v in (*(res.q_program[i] * deg), *(q_w[i] * deg))]
        name = name.replace(",", ";").replace('"', "'")
        row = [name, str(lines_[i]), *vals, f"{err_w[i] * 1e3:.6f}"]
        out.append(",".join([*row, *diagnostics(res, i)]))
    return "\n".join(out) + "\n"


def _echo_cartesian(
    path: str, run: Any, err_c: np.ndarray, rot_c: np.ndarray, emit: Say
) -> None:
    """The Cartesian targets' count, and why each one left is left."""
    if not run.points:
        return
    st = np.asarray(run.status, str)
    for k in np.flatnonzero(st == "left"):
        pt = run.points[k]
        emit(f"{path}: line {pt.line} ({pt.name}): left as written: {run.why[k]}")
    for k, note in run.notes:
        pt = run.points[k]
        emit(f"warning   {path}: line {pt.line} ({pt.name}): {note}")
    ok = st == "ok"
    worst = np.nanmax(err_c[ok]) * 1e3 if ok.any() else 0.0
    worst_r = np.degrees(np.nanmax(rot_c[ok])) if ok.any() else 0.0
    emit(
        f"{path}: {len(st)} Cartesian targets: {int(ok.sum())} corrected, "
        f"{int((st == 'left').sum())} left as written, "
        f"{int(((st != 'ok') & (st != 'left')).sum())} unreachable; largest error of the "
        f"calibrated robot at the corrected targets as the nominal controller reads them "
        f"{worst:.4f} mm, {worst_r:.4f} deg."
    )
