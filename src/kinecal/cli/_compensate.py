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
    robot has at the programmed joints; the rest of the program is kept byte for byte.
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
        res, rows = _program(cal, targets, fmt, tol_mm, scale, decimals)
    bad = [i for i, s in enumerate(res.status) if s != "ok"]
    for i in bad[:50]:
        joint = ""
        if res.limit_joint[i] >= 0:
            joint = f" (J{res.limit_joint[i] + 1} beyond its limit)"
        click.echo(
            f"{targets}: {rows.where[i]}: {res.status[i]}{joint}: predicted error "
            f"{res.error[i] * 1e3:.4f} mm",
            err=True,
        )
    if len(bad) > 50:
        click.echo(f"... and {len(bad) - 50} more rows", err=True)
    ok = res.status == "ok"
    summary = {
        "n": len(res.status),
        "ok": int(ok.sum()),
        "unreachable": len(bad),
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


def _program(cal, path: str, fmt: str, tol_mm: float, scale, decimals):
    import numpy as np

    from kinecal.compensation import compensate as run_compensation
    from kinecal.compensation import program_targets
    from kinecal.io import (
        atomic_write_files,
        program_bytes,
        program_joints,
        read_program,
        write_program,
        written_joints,
    )
    from kinecal.models import ModelInputs

    robot = cal.model.robot
    prog = read_program(path, fmt)
    q_prog = program_joints(prog, robot)
    N = q_prog.shape[0]
    _warn_extrapolation(cal, q_prog, range(1, N + 1), f"{path} (targets in order)")
    p_t, R_t = program_targets(cal, q_prog)
    ls = None if scale is None else np.full(N, scale)
    res = run_compensation(
        cal, p_t, q_prog, R_target=R_t, load_scale=ls, tol=tol_mm * 1e-3
    )
    if prog.skipped:
        click.echo(
            f"{path}: {prog.skipped} Cartesian targets left as they are (only joint "
            "targets are compensated).",
            err=True,
        )
    keep = res.status != "ok"
    text = write_program(prog, res.q_ctrl, robot, decimals=decimals, keep=keep)
    # The predicted error of what is written (the joints rounded to the file's decimals).
    q_w = written_joints(prog, text, robot)
    out = cal.model.evaluate(cal.params, ModelInputs.make(q_w, load_scale=ls)).p_user
    err_w = np.linalg.norm(out - p_t, axis=1)

    def write(out_path, report_path, force):
        files: dict[str, bytes | str] = {out_path: program_bytes(text)}
        if report_path:
            head = [
                "point",
                "line",
                *(f"j{k + 1}_program" for k in range(robot.n_joints)),
            ]
            head += [f"j{k + 1}" for k in range(robot.n_joints)]
            lines = [",".join([*head, "err_written_mm", *_DIAG_HEADER])]
            deg = np.where(robot.prismatic, 1e3, 180.0 / np.pi)
            for i, pt in enumerate(prog.points):
                vals = [f"{v:.8f}" for v in (*(q_prog[i] * deg), *(q_w[i] * deg))]
                name = pt.name.replace(",", ";").replace('"', "'")
                row = [name, str(pt.line), *vals, f"{err_w[i] * 1e3:.6f}"]
                lines.append(",".join([*row, *_diagnostics(res, i)]))
            files[report_path] = "\n".join(lines) + "\n"
        atomic_write_files(files, force=force)  # the program and its report, or neither
        click.echo(
            f"{path}: {int((~keep).sum())} joint targets corrected; largest error as "
            f"written {err_w[~keep].max() * 1e3 if (~keep).any() else 0:.4f} mm "
            "(the joints rounded to the file's decimals).",
            err=True,
        )

    where = [f"line {pt.line} ({pt.name})" for pt in prog.points]
    return res, _Output(where, write)


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
