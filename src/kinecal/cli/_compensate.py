"""``kinecal compensate`` (files: docs/files.md; program files: issue 23)."""

from __future__ import annotations

import json
from pathlib import Path
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
_PROGRAM_ONLY = ("decimals", "report_path", "uframes", "utools", "frames_path",
                 "registers")  # fmt: skip


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
    "--registers",
    type=click.Path(dir_okay=False, exists=True),
    help="FANUC: the controller's POSREG.VA. The position registers the program moves "
    "to are corrected (in the UFRAME_NUM/UTOOL_NUM it selects) and written as a TP "
    "program setting them: --out's name with _PR (CORRECTED_PR.LS).",
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
    registers: str | None,
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
    from kinecal import io
    from kinecal.workflows import compensate_program, compensate_targets
    from kinecal.workflows._compensate_cartesian import frames_of

    fmt = fmt or io.detect_program_format(targets) or "csv"
    if not Path(targets).is_file():
        raise FileNotFoundError(f"{targets}: file not found.")
    pr_path = registers and str(Path(out_path).with_stem(Path(out_path).stem + "_PR"))
    _check_outputs(targets, fmt, out_path, report_path, force, pr_path)
    say = Progress(quiet)  # lines only for stages that last (many targets)
    cal = io.load_model(model_path)
    say.begin("compensate", f"reading {targets} and solving")
    if fmt == "csv":
        run: Any = compensate_targets(
            cal, targets, tol_mm=tol_mm, payload_kg=payload_kg,
            allow_out_of_limits=allow_out_of_limits, say=_stderr,
        )  # fmt: skip
        files: dict[str, bytes | str] = {}
    else:
        uf, ut = frames_of(fmt, uframes, utools, frames_path)
        run = compensate_program(
            cal, targets, fmt, tol_mm=tol_mm, payload_kg=payload_kg,
            decimals=decimals, uframes=uf, utools=ut, say=_stderr,
            registers=registers, registers_name=Path(pr_path or "KC_PR").stem,
        )  # fmt: skip
        files = {out_path: io.program_bytes(run.text)}
        if report_path:
            files[report_path] = run.report
        if pr_path and run.registers:
            files[pr_path] = run.registers
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
        io.atomic_write_text(out_path, run.csv_text(), force=force)
    else:
        io.atomic_write_files(
            files, force=force
        )  # the program and its report, or neither
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
    targets: str, fmt: str, out_path: str, report_path: str | None, force: bool,
    pr_path: str | None,
) -> None:  # fmt: skip
    """Refuse an --out of another kind than the input, or files there without --force
    (before the work, not after it)."""
    from pathlib import Path

    from kinecal.io import detect_program_format
    from kinecal.io._files import check_distinct_outputs

    if fmt == "csv":  # issue 35: they were ignored on a CSV of targets
        refuse_unused(dict.fromkeys(_PROGRAM_ONLY, "is for program files"))
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
    if pr_path and fmt != "fanuc-ls":
        raise click.BadParameter(f"is for FANUC programs; {targets} is {fmt}.",
                                 param_hint="--registers")  # fmt: skip
    check_distinct_outputs([out_path, report_path, pr_path])
    for p in (out_path, report_path, pr_path):
        if p and Path(p).exists() and not force:
            raise FileExistsError(f"{p}: exists; use --force to overwrite it.")


def _stderr(line: str) -> None:
    click.echo(line, err=True)
