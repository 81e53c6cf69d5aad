"""``kinecal compensate`` (files: docs/files.md; program files: issue 23)."""

from __future__ import annotations

import json
from typing import Any

import click

from kinecal.cli._common import (
    FiniteFloat,
    Progress,
    allow_out_of_limits_option,
    common_options,
    model_file_option,
    refuse_unused,
)

_FORMATS = ("csv", "fanuc-ls", "urscript", "rapid", "krl")
_PROGRAM_ONLY = ("decimals", "report_path", "uframes", "utools", "frames_path")


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
    "RAPID wobj, URScript feature), in the program's units and angles (FANUC W,P,R; KRL "
    "A,B,C; RAPID x,y,z,q1..q4; URScript m, rad). Repeatable. 0 / wobj0: the robot base.",
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
    multiple=True,
    type=click.Path(dir_okay=False),
    help="Program files: the controller's frames (repeatable): YAML {uframe: {ID: [...]}, "
    "utool: {ID: [...]}, posreg: {n: ...}} (numbers as for --uframe); KRL $config.dat; "
    "FANUC SYSFRAME.VA or POSREG.VA (registers corrected into OUT_PR.LS).",
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
    frames_path: tuple[str, ...],
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
    for byte, but for one comment line marking it compensated (such a file, or a
    CORRECTED.csv, is refused as input: never corrected twice). Unreachable or
    out-of-limit rows are listed; exit code 4 unless --allow-unreachable.
    """
    from pathlib import Path

    from kinecal.io import (
        atomic_write_files,
        atomic_write_text,
        detect_program_format,
        load_model,
    )
    from kinecal.workflows import compensate_program, compensate_targets

    fmt = fmt or detect_program_format(targets) or "csv"
    if not Path(targets).is_file():
        raise FileNotFoundError(f"{targets}: file not found.")
    from kinecal.workflows._compensate import register_path

    pr = register_path(out_path)[0] if fmt == "fanuc-ls" and frames_path else None
    _check_outputs(targets, fmt, out_path, report_path, force, pr)
    say = Progress(quiet)  # lines only for stages that last (many targets)
    cal = load_model(model_path)
    say.begin("compensate", f"reading {targets} and solving")
    if fmt == "csv":
        run: Any = compensate_targets(
            cal, targets, tol_mm=tol_mm, payload_kg=payload_kg,
            allow_out_of_limits=allow_out_of_limits, say=_stderr,
        )  # fmt: skip
        files: dict[str, bytes | str] = {}
    else:
        from kinecal.io import program_bytes
        from kinecal.workflows._frames import program_frames

        uf, ut, regs = program_frames(fmt, uframes, utools, frames_path)
        run = compensate_program(
            cal, targets, fmt, tol_mm=tol_mm, payload_kg=payload_kg,
            decimals=decimals, uframes=uf, utools=ut, registers=regs, say=_stderr,
        )  # fmt: skip
        files = {out_path: program_bytes(run.text), **run.register_outputs(out_path)}
        if report_path:
            files[report_path] = run.report
    for line in run.motion_warnings(targets, warn_dq_deg):
        click.echo(line, err=True)
    bad = run.unreachable()
    for line in run.unreachable_lines(targets):
        click.echo(line, err=True)
    summary = {**run.summary(), "out": out_path}
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
    if fmt == "csv":
        atomic_write_text(out_path, run.csv_text(), force=force)
    else:
        atomic_write_files(files, force=force)  # the program and its report, or neither
    program = fmt != "csv"
    _print_result(
        summary, as_json, program and run.written_note, program and report_path
    )


def _print_result(
    summary: dict[str, Any], as_json: bool, note: Any, report: Any
) -> None:
    """A program's written ``note`` (stderr), then the summary: JSON or one line
    (``report``: the program's report file, if written)."""
    if note:
        click.echo(note, err=True)
    if as_json:
        click.echo(json.dumps(summary))
        return
    click.echo(
        f"{summary['ok']} of {summary['n']} targets compensated; largest predicted "
        f"error {summary['max_err_mm'] or 0:.6f} mm; wrote {summary['out']}"
        + (f" and {report}" if report else "")
    )


def _check_outputs(
    targets: str, fmt: str, out: str, report: str | None, force: bool, pr: str | None
) -> None:
    """Refuse an --out of another kind than the input, or files there without --force
    (before the work, not after it); ``pr``: a FANUC register program written beside."""
    from pathlib import Path

    from kinecal.io import detect_program_format
    from kinecal.io._files import check_distinct_outputs

    if fmt == "csv":  # issue 35: they were ignored on a CSV of targets
        refuse_unused(dict.fromkeys(_PROGRAM_ONLY, "is for program files"))
    # The output is of the input's kind: an --out named for another kind would hold
    # what its name does not say (a FANUC program in c.csv).
    suffix = Path(out).suffix.lower()
    out_kind = "csv" if suffix == ".csv" else detect_program_format(out)
    if out_kind is not None and out_kind != fmt:
        want = "a CSV file (.csv)" if fmt == "csv" else f"a {fmt} program"
        raise click.BadParameter(
            f"{out}: the corrected {targets} is {want}; name --out for it "
            f"(as {Path(targets).suffix or '.csv'}), not {suffix}.",
            param_hint="--out",
        )
    check_distinct_outputs([out, report, pr])
    for p in (out, report, pr):
        if p and Path(p).exists() and not force:
            raise FileExistsError(f"{p}: exists; use --force to overwrite it.")


def _stderr(line: str) -> None:
    click.echo(line, err=True)
