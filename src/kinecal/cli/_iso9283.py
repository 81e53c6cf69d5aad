"""ISO 9283 hooks of ``kinecal plan --iso9283`` and ``kinecal evaluate --iso9283``.

The options, argument checks, writing and printing live here (the work: the workflows of
:mod:`kinecal.workflows._iso9283`); ``cli/_plan.py`` and ``cli/_calibrate.py`` only apply
the option decorators and call :func:`run_iso_plan` / :func:`run_iso_evaluate`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from kinecal.cli._common import (
    FiniteFloat,
    Progress,
    option_table,
    parse_floats,
    parse_pose,
    refuse_unused,
)

_PLAN_FLAGS = ("candidates", "poses", "add_n")
_NOT_ISO = ("criterion", "exchange", "instrument", "targets", "noise_mm", "noise_deg",
    "priors", "user_frame", "save_candidates", "data_path", "random_draws", "joint_range",
    "n_candidates", "min_j5_deg", "min_conditioning", "floor_mm", "station", "cone_deg",
    "standoff_mm")  # fmt: skip


# fmt: off
# The ``--iso9283`` options of ``kinecal plan``.
iso_plan_options = option_table([
    (("--iso9283",), {"is_flag": True, "help": "Write the ISO 9283 pose test instead: "
        "the cube's test points P1-P5 in cycles (P1, P5, P4, P3, P2), joints by the "
        "nominal IK (compensated with --model MODEL.yaml when given), columns iso_point, "
        "iso_cycle and the command pose cmd_*."}),
    (("--cube-mm",), {"type": FiniteFloat(0.0, low_open=True), "help": "ISO 9283: cube "
        "edge [mm; default the largest reachable]."}),
    (("--cube-centre",), {"metavar": "X,Y,Z", "help": "ISO 9283: cube centre in the "
        "robot base frame [mm; default searched in front of the robot]."}),
    (("--cycles",), {"type": click.IntRange(min=2), "default": 30, "show_default": True,
        "help": "ISO 9283: cycles of the test."}),
    (("--orientation",), {"metavar": "R,W,P", "help": "ISO 9283: tool orientation in "
        "the robot base frame [deg; Rz(R) Ry(W) Rx(P); default the tool z axis down: "
        "0,0,180]."}),
    (("--iso-plane",), {"type": click.Choice(("C1-C2-C7-C8", "C2-C3-C8-C5",
        "C3-C4-C5-C6", "C4-C1-C6-C7")), "default": "C1-C2-C7-C8", "show_default": True,
        "help": "ISO 9283: the cube's diagonal test plane."}),
])
# fmt: on


def run_iso_plan(kw: dict[str, Any], say: Progress) -> None:
    """``kinecal plan --iso9283``: PLAN.csv and PLAN.report.json."""
    import numpy as np

    from kinecal.geometry import euler_zyx_to_matrix
    from kinecal.io import atomic_write_files, json_text
    from kinecal.io._files import check_distinct_outputs
    from kinecal.robot import load_robot
    from kinecal.workflows import iso_test_program
    from kinecal.workflows._plan import model_robot, report_path

    given = [f"--{k.replace('_n', '')}" for k in _PLAN_FLAGS if kw.get(k)]
    if given:
        raise click.UsageError(
            f"--iso9283 writes the standard's test poses; {', '.join(given)} choose "
            "calibration poses (give one or the other)."
        )
    refuse_unused(dict.fromkeys(_NOT_ISO, "chooses calibration poses, not --iso9283"))
    cal = None
    if kw["model_name"] not in ("kinematic", "ntm", "rfcm", "full"):
        from kinecal.io import load_model

        cal = load_model(kw["model_name"])  # compensate the program with it
        if kw["tool"]:
            raise click.UsageError("--tool: a calibrated model has its own tool frame.")
    if not kw["robot_name"] and cal is None:
        raise click.UsageError(
            "--iso9283 needs --robot NAME|FILE (or --model MODEL.yaml)."
        )
    out = Path(kw["out_path"])
    rep = report_path(kw["out_path"], kw["report_path"])
    check_distinct_outputs([out, rep])
    for p in (out, rep):
        if p.exists() and not kw["force"]:
            raise FileExistsError(f"{p} exists; use --force to overwrite it.")
    if kw["robot_name"]:
        robot = load_robot(kw["robot_name"])
    else:
        assert cal is not None  # checked above
        robot = cal.model.robot
    if cal is not None:  # --robot, when given, names the model's robot
        model_robot(cal, kw["robot_name"], kw["model_name"])
    R = None
    if kw["orientation"]:
        rwp = parse_floats(kw["orientation"], 3, "--orientation")
        R = euler_zyx_to_matrix(np.radians(rwp))
    centre = None
    if kw["cube_centre"]:
        c = parse_floats(kw["cube_centre"], 3, "--cube-centre")
        centre = (c[0], c[1], c[2])
    T_tool = parse_pose(kw["tool"] or None, "--tool", (3, 6))  # the cube's tool point
    prog = iso_test_program(
        robot, cal=cal, edge_mm=kw["cube_mm"], centre_mm=centre, R_base_tool=R,
        cycles=kw["cycles"], plane=kw["iso_plane"], seed=kw["seed"],
        T_flange_tool=T_tool, model_name=kw["model_name"], progress=say,
    )  # fmt: skip
    files = {str(out): prog.csv_text(), str(rep): json_text(prog.report)}
    lines = (  # before the files: a failure leaves them as they were
        [json.dumps(prog.report)]
        if kw["as_json"]
        else [*prog.summary_lines(), f"wrote     {out}, {rep}"]
    )
    atomic_write_files(files, force=kw["force"])
    click.echo("\n".join(lines))


def iso_evaluate_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """The ``--iso9283`` options of ``kinecal evaluate``."""
    f = click.option(
        "--out",
        "iso_out",
        type=click.Path(file_okay=False),
        help="With --iso9283: folder for report.json (an iso9283 block) and "
        "report.html.",
    )(f)
    return click.option(
        "--iso9283",
        is_flag=True,
        help="ISO 9283 figures of a pose test (plan --iso9283 with measured x_mm.. "
        "and iso_point, iso_cycle columns): AP, RP per point, AD, RD; with the model "
        "and with the nominal robot.",
    )(f)


def run_iso_evaluate(
    cal: Any,
    meas: Any,
    data: str,
    refit: tuple[str, ...],
    out_dir: str | None,
    force: bool,
    as_json: bool,
    model_path: str,
    files: dict[str, str] | None = None,
) -> None:
    """``kinecal evaluate --iso9283``: console table, optional report.json/.html;
    ``files`` (--errors-out) written with them, once the figures are in."""
    from kinecal.io import atomic_write_files, json_text
    from kinecal.workflows import evaluate_iso_test

    folder = None
    if out_dir:  # the command's staged folder, moved into place when it succeeds
        from kinecal.io import prepare_output_dir

        folder = prepare_output_dir(
            out_dir, ["report.json", "report.html"], force=force
        )
    res = evaluate_iso_test(cal, meas, data, refit=refit)
    block = res.block
    lines = [json.dumps({"iso9283": block})] if as_json else res.table_lines()
    if folder is not None:
        from kinecal.report._iso9283 import render_iso9283_report

        doc = {"data": data, "model": model_path, "iso9283": block}
        title = f"ISO 9283 evaluation: {Path(data).name}"
        atomic_write_files(
            {
                str(folder / "report.json"): json_text(doc),
                str(folder / "report.html"): render_iso9283_report(block, title=title),
            },
            force=True,
        )
    atomic_write_files(files or {}, force=force)
    click.echo("\n".join(lines))
    if out_dir and not as_json:
        click.echo(f"wrote     {out_dir}: report.json, report.html")
