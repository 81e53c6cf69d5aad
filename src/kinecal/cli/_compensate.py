"""``kinecal compensate`` (files: docs/files.md; program files: issue 23)."""

from __future__ import annotations

import json

import click

from kinecal.cli._common import (
    FiniteFloat,
    Progress,
    allow_out_of_limits_option,
    check_positions,
    common_options,
    echo_diagnostics,
    model_file_option,
)

_FORMATS = ("csv", "fanuc-ls", "urscript", "rapid", "krl")


@click.command()
@click.argument("targets", type=click.Path(dir_okay=False))
@model_file_option
@click.option(
    "--out",
    "out_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="CORRECTED.csv (the same rows with corrected joints; the program's joints kept in "
    "j*_program columns; rot_err_deg, dq_max_deg, cond, limit_joint (1-based, 0: none), "
    "err_mm, status), or the corrected program.",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(_FORMATS),
    help="Input format (default: from the extension: .ls FANUC TP, .script URScript, "
    ".mod/.modx/.prg ABB RAPID, .src/.dat KUKA KRL, else CSV).",
)
@click.option(
    "--tol-mm",
    type=FiniteFloat(0.0, low_open=True),
    default=0.001,
    show_default=True,
    help="A row is reachable when the model's predicted error is below this [mm].",
)
@click.option(
    "--payload-kg",
    type=FiniteFloat(0.0),
    help="Payload at the tool [kg] (default: the calibration's reference payload).",
)
@click.option(
    "--decimals",
    type=click.IntRange(0, 12),
    help="Program files: decimals of the written joints (default: the file's, at least "
    "FANUC 3, URScript 8, RAPID/KRL 4).",
)
@click.option(
    "--report",
    "report_path",
    type=click.Path(dir_okay=False),
    help="Program files: a CSV with one row per joint target (program and corrected "
    "joints, predicted error, condition number, status).",
)
@click.option(
    "--allow-unreachable",
    is_flag=True,
    help="Write the file even if some rows are unreachable (they are flagged; in a "
    "program they keep their joints).",
)
@click.option(
    "--uframe",
    "uframes",
    multiple=True,
    metavar="ID=x,y,z,a,b,c",
    help="Program files: a user frame the Cartesian targets name (FANUC UF, KRL BASE_NO, "
    "RAPID wobj), in the program's units and angles (FANUC W,P,R; KRL A,B,C; RAPID "
    "x,y,z,q1..q4). Repeatable. 0 / wobj0: the robot base.",
)
@click.option(
    "--utool",
    "utools",
    multiple=True,
    metavar="ID=x,y,z,a,b,c",
    help="Program files: a tool frame (FANUC UT, KRL TOOL_NO, RAPID tooldata) in the "
    "flange frame, as --uframe. 0 / tool0: the flange.",
)
@click.option(
    "--frames",
    "frames_path",
    type=click.Path(dir_okay=False),
    help="Program files: a YAML file of the controller's frames, {uframe: {ID: [...]}, "
    "utool: {ID: [...]}} (numbers as for --uframe); for KRL also the controller's "
    "$config.dat (BASE_DATA[n], TOOL_DATA[n]).",
)
@click.option(
    "--warn-dq-deg",
    type=FiniteFloat(0.0),
    default=1.0,
    show_default=True,
    help="Warn for every target whose correction moves a joint by more than this [deg].",
)
@allow_out_of_limits_option
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary.")
@click.option("--force", is_flag=True, help="Overwrite --out.")
@common_options
def compensate(
    targets: str,
    model_path: str,
    out_path: str,
    fmt: str | None,
    tol_mm: float,
    payload_kg: float | None,
    decimals: int | None,
    report_path: str | None,
    allow_unreachable: bool,
    uframes: tuple[str, ...],
    utools: tuple[str, ...],
    frames_path: str | None,
    warn_dq_deg: float,
    allow_out_of_limits: bool,
    as_json: bool,
    force: bool,
    quiet: bool,
) -> None:
    """Corrected controller angles so the robot reaches TARGETS.

    TARGETS.csv has x_mm, y_mm, z_mm (tool point wanted in the user frame; optional
    qw..qz) and the program's nominal joints j1_deg..jN_deg as seeds (they pick the IK
    branch). A position-only target keeps the seed's tool orientation wherever the pose
    is not nearly singular. A program file (FANUC .ls, URScript, ABB RAPID, KUKA KRL):
    each joint target is moved so that the real robot takes the flange pose the nominal
    robot has at the programmed joints; each Cartesian target (in its user and tool
    frames: --uframe/--utool/--frames) becomes the pose the nominal controller must be
    commanded for the real robot to reach it, configuration flags kept; every target is
    counted (corrected, left and why, unreachable); the rest of the program is kept byte
    for byte.
    Unreachable or out-of-limit rows are listed, and the command exits with code 4
    unless --allow-unreachable.
    """
    from pathlib import Path

    from kinecal.io import detect_program_format, load_model

    fmt = fmt or detect_program_format(targets) or "csv"
    if not Path(targets).is_file():
        raise FileNotFoundError(f"{targets}: file not found.")
    # The output is of the input's kind: an --out named for another kind would hold
    # what its name does not say (a FANUC program in c.csv).
    suffix = Path(out_path).suffix.lower()
    out_kind = "csv" if suffix == ".csv" else detect_program_format(out_path)
    if out_kind is not None and out_kind != fmt:
        want = "a CSV file (.csv)" if fmt == "csv" else f"a {fmt} program"
        raise click.BadParameter(
            f"{out_path}: the corrected {targets} is {want}; name --out for it "
            f"(as {Path(targets).suffix or '.csv'}), not {suffix}.",
            param_hint="--out",
        )
    for p in (out_path, report_path):  # refuse before the work, not after it
        if p and Path(p).exists() and not force:
            raise FileExistsError(f"{p}: exists; use --force to overwrite it.")
    say = Progress(quiet)  # lines only for stages that last (many targets)
    cal = load_model(model_path)
    scale = _load_scale(cal, payload_kg)
    say.begin("compensate", f"reading {targets} and solving")
    if fmt == "csv":
        res, rows = _csv(cal, targets, tol_mm, scale, allow_out_of_limits)
    else:
        frames = _frames(fmt, uframes, utools, frames_path)
        res, rows = _program(cal, targets, fmt, tol_mm, scale, decimals, frames)
    _warn_motion(targets, res, rows, warn_dq_deg)
    bad = [i for i, s in enumerate(res.status) if s not in ("ok", "left")]
    _echo_bad(targets, res, rows, bad)
    ok = res.status == "ok"
    summary = {
        "n": len(res.status),
        "ok": int(ok.sum()),
        "unreachable": len(bad),
        "left": int((res.status == "left").sum()),
        "max_err_mm": float(res.error[ok].max() * 1e3) if ok.any() else None,
        "max_dq_deg": float(_dq_deg(res)[ok].max()) if ok.any() else None,
        "out": out_path,
    }
    if bad and not allow_unreachable:
        from kinecal.cli._errors import CommandFailed, ExitCode

        summary["out"] = None
        if as_json:
            click.echo(json.dumps(summary))
        raise CommandFailed(
            ExitCode.UNREACHABLE,
            f"{targets}: {len(bad)} of {summary['n']} targets cannot be reached; "
            "nothing written (--allow-unreachable writes them flagged).",
        )
    rows.write(out_path, report_path, force)
    if as_json:
        click.echo(json.dumps(summary))
    else:
        click.echo(
            f"{summary['ok']} of {summary['n']} targets compensated; largest predicted "
            f"error {summary['max_err_mm'] or 0:.6f} mm; wrote {out_path}"
            + (f" and {report_path}" if report_path and fmt != "csv" else "")
        )


def _echo_bad(path, res, rows, bad):
    """The unreachable or out-of-limit rows on stderr (the first 50)."""
    for i in bad[:50]:
        joint = ""
        if res.limit_joint[i] >= 0:
            joint = f" (J{res.limit_joint[i] + 1} beyond its limit)"
        click.echo(
            f"{path}: {rows.where[i]}: {res.status[i]}{joint}: predicted error "
            f"{res.error[i] * 1e3:.4f} mm",
            err=True,
        )
    if len(bad) > 50:
        click.echo(f"... and {len(bad) - 50} more rows", err=True)


def _frames(fmt, uframes, utools, frames_path):
    """(uframes, utools) of a program run: --frames, then --uframe/--utool over it."""
    from kinecal.cli._compensate_cartesian import load_frames_file, parse_frames

    uf, ut = load_frames_file(frames_path, fmt) if frames_path else ({}, {})
    uf.update(parse_frames(uframes, fmt, "--uframe"))
    ut.update(parse_frames(utools, fmt, "--utool"))
    return uf, ut


def _warn_motion(path, res, rows, warn_dq_deg):
    """Warnings for corrections that move a joint far, and for singular poses solved
    with the least joint motion."""
    import numpy as np

    dq = np.degrees(np.abs(res.joint_change))
    moved = np.flatnonzero((res.status == "ok") & (dq.max(axis=1) > warn_dq_deg))
    for i in moved[:50]:
        j = int(np.argmax(dq[i]))
        click.echo(
            f"warning   {path}: {rows.where[i]}: the correction moves J{j + 1} by "
            f"{dq[i, j]:.3f} deg (more than --warn-dq-deg {warn_dq_deg:g})",
            err=True,
        )
    relaxed = np.zeros(0, int) if res.relaxed is None else np.flatnonzero(res.relaxed)
    for i in relaxed[:50]:
        click.echo(
            f"warning   {path}: {rows.where[i]}: next to a singular pose: position met, "
            f"the tool turned {np.degrees(res.rotation_error[i]):.4f} deg from the wanted "
            "orientation to keep the joints still (largest joint change "
            f"{dq[i].max():.4f} deg)",
            err=True,
        )


def _load_scale(cal, payload_kg):
    from kinecal.errors import DataError

    if payload_kg is None:
        return None
    if not payload_kg >= 0:
        raise DataError(f"--payload-kg must be >= 0; got {payload_kg}.")
    ref = cal.reference_payload_kg
    if ref is None:
        if cal.model.spec.load:
            raise DataError(
                "the model has no reference payload (its compliance is per unit of the "
                "calibration's load): --payload-kg cannot be used."
            )
        return None
    return payload_kg / ref


def _dq_deg(res):
    import numpy as np

    return np.degrees(np.abs(res.joint_change)).max(axis=1)


class _Output:
    """What a run writes, and how each row is named in messages."""

    def __init__(self, where, write):
        self.where = where
        self.write = write


def _diagnostics(res, i: int) -> list[str]:
    """The diagnostic columns of row i: every one numeric, the status last."""
    import numpy as np

    return [
        f"{np.degrees(res.rotation_error[i]):.6f}",
        f"{_dq_deg(res)[i]:.6f}",
        f"{res.cond[i]:.4g}",
        str(int(res.limit_joint[i]) + 1),  # 1-based; 0: none
        f"{res.error[i] * 1e3:.6f}",
        str(res.status[i]),
    ]


# err_mm and status stay the last two columns, as before issue 23.
_DIAG_HEADER = ["rot_err_deg", "dq_max_deg", "cond", "limit_joint", "err_mm", "status"]


def _diagnostic_columns(res):
    """The diagnostic columns of every row at once (as :func:`_diagnostics` per row)."""
    import numpy as np

    from kinecal.io import Column

    values = (
        Column.numbers(np.degrees(res.rotation_error), "%.6f"),
        Column.numbers(_dq_deg(res), "%.6f"),
        Column.numbers(res.cond, "%.4g"),
        Column.numbers(np.asarray(res.limit_joint) + 1, "%d"),  # 1-based; 0: none
        Column.numbers(res.error * 1e3, "%.6f"),
        Column.text([str(x) for x in res.status]),
    )
    return list(zip(_DIAG_HEADER, values))


def _warn_extrapolation(cal, q, rows, source: str) -> None:
    """Targets outside the joint ranges the model was calibrated on (a warning)."""
    from kinecal.io import extrapolation

    found = extrapolation(cal, q, rows, source, what="targets")
    echo_diagnostics([] if found is None else [found])


def _csv(cal, targets: str, tol_mm: float, scale, allow_out_of_limits: bool):
    import numpy as np

    from kinecal.compensation import compensate as run_compensation
    from kinecal.io import atomic_write_text, read_compensation_targets

    tg = read_compensation_targets(
        targets, cal.model.robot, allow_out_of_limits=allow_out_of_limits
    )
    echo_diagnostics(tg.diagnostics)
    _warn_extrapolation(cal, tg.q_seed, tg.table.lines, targets)
    check_positions(tg.p, tg.table.lines, targets, "x_mm, y_mm, z_mm")
    spec = cal.model.spec
    set_index = _map_labels(tg.set_labels, tg.set_index, spec.sets, targets, "set")
    marker_index = _map_labels(
        tg.marker_labels, tg.marker_index, spec.markers, targets, "marker"
    )
    N = tg.p.shape[0]
    res = run_compensation(
        cal,
        tg.p,
        tg.q_seed,
        R_target=tg.R,
        set_index=set_index,
        marker_index=marker_index,
        load_scale=None if scale is None else np.full(N, scale),
        tol=tol_mm * 1e-3,
    )
    to_file = {"deg": 180.0 / np.pi, "rad": 1.0, "mm": 1e3, "m": 1.0}

    def write(out_path, _report, force):
        from kinecal.io import Column, table_csv

        new = {
            c: Column.numbers(res.q_ctrl[:, k] * to_file[c.rsplit("_", 1)[1]], "%.8f")
            for k, c in enumerate(tg.joint_columns)
        }
        cols = [(c, new.get(c) or Column.copy_of(c)) for c in tg.table.header]
        cols += [(f"{c}_program", Column.copy_of(c)) for c in tg.joint_columns]
        text = table_csv(tg.table, cols + _diagnostic_columns(res))
        atomic_write_text(out_path, text, force=force)

    where = [f"line {ln}" for ln in tg.table.lines]
    return res, _Output(where, write)


def _joint_part(cal, prog, scale, tol_mm):
    """Compensate the joint targets of a program: (q_prog, p_t, res, ls)."""
    import numpy as np

    from kinecal.compensation import compensate as run_compensation
    from kinecal.compensation import program_targets
    from kinecal.io import program_joints

    q_prog = program_joints(prog, cal.model.robot)
    N = q_prog.shape[0]
    ls = None if scale is None else np.full(N, scale)
    if N == 0:
        return q_prog, np.zeros((0, 3)), None, ls
    p_t, R_t = program_targets(cal, q_prog)
    res = run_compensation(
        cal, p_t, q_prog, R_target=R_t, load_scale=ls, tol=tol_mm * 1e-3
    )
    return q_prog, p_t, res, ls


def _joined(res, run, n):
    """The joint targets' result and the Cartesian targets' as one CompensationResult
    (Cartesian targets left as written: status 'left', NaN errors)."""
    import numpy as np

    from kinecal.compensation import CompensationResult

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


def _program(cal, path: str, fmt: str, tol_mm: float, scale, decimals, frames):
    import numpy as np

    from kinecal.cli._compensate_cartesian import cartesian_run, written_errors
    from kinecal.io import (
        atomic_write_files,
        program_bytes,
        read_program,
        write_program,
        written_joints,
    )
    from kinecal.models import ModelInputs

    robot = cal.model.robot
    prog = read_program(path, fmt)
    q_prog, p_t, res_j, ls = _joint_part(cal, prog, scale, tol_mm)
    uframes, utools = frames
    run = cartesian_run(cal, prog, q_prog, uframes, utools, scale, tol_mm, decimals)
    q_all = np.vstack([q_prog, run.q_seed[np.all(np.isfinite(run.q_seed), axis=1)]])
    _warn_extrapolation(
        cal, q_all, range(1, q_all.shape[0] + 1), f"{path} (targets in order)"
    )
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
    res = _joined(res_j, run, robot.n_joints)
    names = [pt.name for pt in prog.points] + [
        f"{pt.name}, Cartesian" for pt in run.points
    ]
    lines_ = [pt.line for pt in prog.points] + [pt.line for pt in run.points]
    q_w_all = np.vstack([q_w, np.nan_to_num(run.q_new)])
    err_all = np.concatenate([err_w, err_c])
    _echo_cartesian(path, run, err_c, rot_c)

    def write(out_path, report_path, force):
        files: dict[str, bytes | str] = {out_path: program_bytes(text)}
        if report_path:
            files[report_path] = _report_text(
                res, names, lines_, q_w_all, err_all, robot
            )
        atomic_write_files(files, force=force)  # the program and its report, or neither
        n_j = int((~keep).sum())
        if keep.size == 0:
            return
        click.echo(
            f"{path}: {n_j} joint targets corrected; largest error as "
            f"written {err_w[~keep].max() * 1e3 if n_j else 0:.4f} mm "
            "(the joints rounded to the file's decimals).",
            err=True,
        )

    where = [f"line {ln} ({nm})" for ln, nm in zip(lines_, names)]
    return res, _Output(where, write)


def _report_text(res, names, lines_, q_w, err_w, robot):
    import numpy as np

    head = ["point", "line", *(f"j{k + 1}_program" for k in range(robot.n_joints))]
    head += [f"j{k + 1}" for k in range(robot.n_joints)]
    out = [",".join([*head, "err_written_mm", *_DIAG_HEADER])]
    deg = np.where(robot.prismatic, 1e3, 180.0 / np.pi)
    for i, name in enumerate(names):
        vals = [f"{v:.8f}" for v in (*(res.q_program[i] * deg), *(q_w[i] * deg))]
        name = name.replace(",", ";").replace('"', "'")
        row = [name, str(lines_[i]), *vals, f"{err_w[i] * 1e3:.6f}"]
        out.append(",".join([*row, *_diagnostics(res, i)]))
    return "\n".join(out) + "\n"


def _echo_cartesian(path, run, err_c, rot_c):
    """The Cartesian targets' count on stderr, and why each one left is left."""
    import numpy as np

    if not run.points:
        return
    st = np.asarray(run.status, str)
    for k in np.flatnonzero(st == "left"):
        pt = run.points[k]
        click.echo(
            f"{path}: line {pt.line} ({pt.name}): left as written: {run.why[k]}",
            err=True,
        )
    for k, note in run.notes:
        pt = run.points[k]
        click.echo(f"warning   {path}: line {pt.line} ({pt.name}): {note}", err=True)
    ok = st == "ok"
    worst = np.nanmax(err_c[ok]) * 1e3 if ok.any() else 0.0
    worst_r = np.degrees(np.nanmax(rot_c[ok])) if ok.any() else 0.0
    click.echo(
        f"{path}: {len(st)} Cartesian targets: {int(ok.sum())} corrected, "
        f"{int((st == 'left').sum())} left as written, "
        f"{int(((st != 'ok') & (st != 'left')).sum())} unreachable; largest error of the "
        f"calibrated robot at the corrected targets as the nominal controller reads them "
        f"{worst:.4f} mm, {worst_r:.4f} deg.",
        err=True,
    )


def _map_labels(labels, index, own, path, what):
    """Map the file's set/marker labels onto the model's (one frame: any label)."""
    import numpy as np

    from kinecal.errors import DataError

    if len(own) == 1:
        return np.zeros(index.shape[0], np.intp)
    missing = [lab for lab in labels if lab not in own]
    if missing:
        raise DataError(
            f"{path}: {what} {missing[0]!r} is not in the model ({', '.join(own)})."
        )
    return np.array([own.index(lab) for lab in labels], np.intp)[index]
