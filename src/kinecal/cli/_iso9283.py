"""ISO 9283 hooks of ``kinecal plan --iso9283`` and ``kinecal evaluate --iso9283``.

The options and the work live here; ``cli/_plan.py`` and ``cli/_calibrate.py`` only apply
the option decorators and call :func:`run_iso_plan` / :func:`run_iso_evaluate`.
File columns (docs/iso9283.md): the plan's joint columns, ``iso_point`` (P1..P5),
``iso_cycle`` (1..n), ``cmd_x_mm, cmd_y_mm, cmd_z_mm`` (command position in the robot
base frame) and ``cmd_a_deg, cmd_b_deg, cmd_c_deg`` (command orientation about x, y, z).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from kinecal.cli._common import FiniteFloat, Progress

POINT_COLUMN, CYCLE_COLUMN = "iso_point", "iso_cycle"
_PLAN_FLAGS = ("candidates", "poses", "add_n")


def iso_plan_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """The ``--iso9283`` options of ``kinecal plan``."""
    opts = [
        click.option(
            "--iso9283",
            is_flag=True,
            help="Write the ISO 9283 pose test instead: the cube's test points P1-P5 "
            "in cycles (P1, P5, P4, P3, P2), joints by the nominal IK (compensated "
            "with --model MODEL.yaml when given), columns iso_point, iso_cycle and the "
            "command pose cmd_*.",
        ),
        click.option(
            "--cube-mm",
            type=FiniteFloat(0.0, low_open=True),
            help="ISO 9283: cube edge [mm; default the largest reachable].",
        ),
        click.option(
            "--cube-centre",
            metavar="X,Y,Z",
            help="ISO 9283: cube centre in the robot base frame [mm; default searched "
            "in front of the robot].",
        ),
        click.option(
            "--cycles",
            type=click.IntRange(min=2),
            default=30,
            show_default=True,
            help="ISO 9283: cycles of the test.",
        ),
        click.option(
            "--orientation",
            metavar="R,W,P",
            help="ISO 9283: tool orientation in the robot base frame [deg; Rz(R) Ry(W) "
            "Rx(P); default the tool z axis down: 0,0,180].",
        ),
        click.option(
            "--iso-plane",
            type=click.Choice(
                ("C1-C2-C7-C8", "C2-C3-C8-C5", "C3-C4-C5-C6", "C4-C1-C6-C7")
            ),
            default="C1-C2-C7-C8",
            show_default=True,
            help="ISO 9283: the cube's diagonal test plane.",
        ),
    ]
    for o in reversed(opts):
        f = o(f)
    return f


def _numbers(text: str, n: int, name: str) -> list[float]:
    import math

    try:
        vals = [float(t) for t in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise click.BadParameter(
            f"expected {n} comma-separated numbers; got {text!r}", param_hint=name
        )
    return vals


def run_iso_plan(kw: dict[str, Any], say: Progress) -> None:
    """``kinecal plan --iso9283``: PLAN.csv and PLAN.report.json."""
    import numpy as np

    from kinecal.geometry import euler_transform, euler_zyx_to_matrix
    from kinecal.io import atomic_write_files, json_text
    from kinecal.iso9283 import POINT_LABELS, VISIT_ORDER, plan_iso9283
    from kinecal.robot import load_robot

    given = [f"--{k.replace('_n', '')}" for k in _PLAN_FLAGS if kw.get(k)]
    if given:
        raise click.UsageError(
            f"--iso9283 writes the standard's test poses; {', '.join(given)} choose "
            "calibration poses (give one or the other)."
        )
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
    rep = (
        Path(kw["report_path"])
        if kw["report_path"]
        else out.with_name(out.stem + ".report.json")
    )
    for p in (out, rep):
        if p.exists() and not kw["force"]:
            raise FileExistsError(f"{p} exists; use --force to overwrite it.")
    if kw["robot_name"]:
        robot = load_robot(kw["robot_name"])
    else:
        assert cal is not None  # checked above
        robot = cal.model.robot
    if cal is not None and robot.name != cal.model.robot.name:
        from kinecal.errors import ConfigError

        raise ConfigError(
            f"--robot {kw['robot_name']}, but {kw['model_name']} was calibrated for "
            f"{cal.model.robot.name}: a model and a robot of different kinds."
        )
    R = None
    if kw["orientation"]:
        rwp = _numbers(kw["orientation"], 3, "--orientation")
        R = euler_zyx_to_matrix(np.radians(rwp))
    centre = None
    if kw["cube_centre"]:
        centre = np.array(_numbers(kw["cube_centre"], 3, "--cube-centre")) * 1e-3
    edge = None if kw["cube_mm"] is None else kw["cube_mm"] * 1e-3
    T_tool = None
    if kw["tool"]:  # the tool point the cube's points are for
        n = len(kw["tool"].split(","))
        tool = _numbers(kw["tool"], n if n in (3, 6) else 6, "--tool") + [0.0] * (6 - n)
        T_tool = euler_transform([*np.array(tool[:3]) * 1e-3, *np.radians(tool[3:])])
    say("iso9283", "placing the cube" if edge is None else "checking the cube")
    pl = plan_iso9283(
        robot,
        edge=edge,
        centre=centre,
        R_base_tool=R,
        cycles=kw["cycles"],
        plane=kw["iso_plane"],
        seed=kw["seed"],
        T_flange_tool=T_tool,
    )
    if cal is not None:
        from kinecal.iso9283 import compensated_plan

        say("iso9283", f"compensating the program with {kw['model_name']}")
        pl = compensated_plan(pl, cal)
    lines, joint_cols, f = _plan_lines(robot, pl)
    doc = _plan_doc(robot, pl, joint_cols, f, kw, cal is not None)
    atomic_write_files(
        {str(out): "\n".join(lines) + "\n", str(rep): json_text(doc)},
        force=kw["force"],
    )
    if kw["as_json"]:
        click.echo(json.dumps(doc))
        return
    cube, pts_mm = pl.cube, pl.cube.points * 1e3
    click.echo(
        f"cube      edge {cube.edge * 1e3:.1f} mm, centre "
        + ", ".join(f"{v:.1f}" for v in cube.centre * 1e3)
        + f" mm (robot base), plane {cube.plane}"
    )
    for i, lab in enumerate(POINT_LABELS):
        click.echo(
            f"{lab}        "
            + ", ".join(f"{v:8.2f}" for v in pts_mm[i])
            + " mm   joints "
            + " ".join(f"{v:.2f}" for v in pl.q_points[i] * f)
        )
    click.echo(
        f"program   {pl.cycles} cycles of {' -> '.join(VISIT_ORDER)}: "
        f"{len(lines) - 1} rows"
    )
    if cal is not None:
        click.echo(
            f"joints    compensated with {kw['model_name']} (the points through its "
            "user frame; evaluate --iso9283 gives the accuracy after compensation)"
        )
    click.echo(f"wrote     {out}, {rep}")


def _plan_lines(robot: Any, pl: Any) -> tuple[list[str], list[str], Any]:
    """The program's CSV lines, its joint columns and their factors from SI."""
    import numpy as np

    from kinecal.iso9283 import POINT_LABELS, orientation_abc

    joint_cols = [
        f"j{k + 1}_mm" if j.kind == "prismatic" else f"j{k + 1}_deg"
        for k, j in enumerate(robot.joints)
    ]
    f = np.array([1e3 if j.kind == "prismatic" else 180 / np.pi for j in robot.joints])
    abc = np.degrees(orientation_abc(pl.R_base_tool))
    cmd_cols = [
        "cmd_x_mm",
        "cmd_y_mm",
        "cmd_z_mm",
        "cmd_a_deg",
        "cmd_b_deg",
        "cmd_c_deg",
    ]
    lines = [",".join([*joint_cols, POINT_COLUMN, CYCLE_COLUMN, *cmd_cols])]
    pts_mm = pl.cube.points * 1e3
    for q, k, c in zip(pl.q_ctrl * f, pl.point_index, pl.cycle):
        cells = [f"{v:.6f}" for v in q] + [POINT_LABELS[k], str(c)]
        cells += [f"{v:.4f}" for v in pts_mm[k]] + [f"{v:.6f}" for v in abc]
        lines.append(",".join(cells))
    return lines, joint_cols, f


def _plan_doc(
    robot: Any, pl: Any, joint_cols: list[str], f: Any, kw: dict[str, Any], comp: bool
) -> dict[str, Any]:
    """The program's report.json."""
    import numpy as np

    from kinecal.iso9283 import POINT_LABELS, VISIT_ORDER, orientation_abc

    abc = np.degrees(orientation_abc(pl.R_base_tool))
    pts_mm = pl.cube.points * 1e3
    cube = pl.cube
    doc = {
        "iso9283_plan": {
            "standard": "ISO 9283:1998, 6.2 (cube, test plane, P1..P5), 7.2.1 (cycles)",
            "robot": robot.name,
            "frame": "robot base (the robot file's base; FANUC: World)",
            "cube": {
                "centre_mm": (cube.centre * 1e3).tolist(),
                "edge_mm": cube.edge * 1e3,
                "plane": cube.plane,
                "diagonal_mm": cube.diagonal * 1e3,
                "corners_mm": {
                    f"C{i + 1}": c.tolist() for i, c in enumerate(cube.corners * 1e3)
                },
            },
            "orientation_abc_deg": abc.tolist(),
            "cycles": pl.cycles,
            "order": list(VISIT_ORDER),
            "points": [
                {
                    "point": lab,
                    "command_mm": pts_mm[i].tolist(),
                    "joints": dict(zip(joint_cols, (pl.q_points[i] * f).tolist())),
                }
                for i, lab in enumerate(POINT_LABELS)
            ],
            "rows": len(pl.point_index),
            "compensated_with": kw["model_name"] if comp else None,
        }
    }
    return doc


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


def read_iso_data(
    data: str, robot: Any, targets: str | None, allow_out_of_limits: bool
) -> Any:
    """The measurements of an ISO test, its findings printed except ``poor_excitation``
    (one tool orientation over a small cube is the test, not a flaw of the data)."""
    from kinecal.cli._common import echo_diagnostics
    from kinecal.io import read_data

    meas, found = read_data(
        data, robot, targets, allow_out_of_limits=allow_out_of_limits
    )
    echo_diagnostics([d for d in found if d.code != "poor_excitation"])
    return meas


def _labels(data: str, rows: Any) -> tuple[Any, Any]:
    """``iso_point`` and ``iso_cycle`` of the data rows (by file line)."""
    import numpy as np

    from kinecal.errors import DataError
    from kinecal.io import read_table

    t = read_table(data)
    # the plan's names, or the plain ones a measurement program may write
    names = {c.strip().lower(): k for k, c in enumerate(t.header)}
    found = [
        next((names[c] for c in (want, want[4:]) if c in names), None)
        for want in (POINT_COLUMN, CYCLE_COLUMN)
    ]
    missing = [c for c, k in zip((POINT_COLUMN, CYCLE_COLUMN), found) if k is None]
    if missing:
        raise DataError(
            f"{data}: no column {' or '.join(repr(c) for c in missing)}; --iso9283 needs "
            f"the test point ({POINT_COLUMN}: P1..P5) and the cycle ({CYCLE_COLUMN}: "
            "1, 2, ...) of every row, as plan --iso9283 writes them (also accepted: "
            "'point', 'cycle')."
        )
    kp, kc = (int(k) for k in found if k is not None)
    by_line = {line: row for line, row in zip(t.lines, t.rows)}
    points, cycles = [], []
    for r in rows:
        row = by_line[int(r)]
        text = row[kc].strip()
        try:
            c = int(text)
            if c < 1 or str(c) != text.lstrip("+"):
                raise ValueError
        except ValueError:
            raise DataError(
                f"{data}: line {r}, column '{t.header[kc]}': {text!r} is not a cycle "
                "number; expected an integer 1, 2, ..."
            ) from None
        points.append(row[kp].strip())
        cycles.append(c)
    return np.array(points, dtype=object), np.array(cycles, dtype=np.intp)


def run_iso_evaluate(
    cal: Any,
    meas: Any,
    data: str,
    refit: tuple[str, ...],
    out_dir: str | None,
    force: bool,
    as_json: bool,
    model_path: str,
) -> None:
    """``kinecal evaluate --iso9283``: console table, optional report.json/.html."""
    from kinecal.iso9283 import evaluate_iso9283

    folder = None
    if out_dir:  # the command's staged folder, moved into place when it succeeds
        from kinecal.io import prepare_output_dir

        folder = prepare_output_dir(
            out_dir, ["report.json", "report.html"], force=force
        )
    point, cycle = _labels(data, meas.rows)
    iso = evaluate_iso9283(cal, meas, point, cycle, refit=refit)
    block = iso.as_dict()
    if folder is not None:
        from kinecal.io import atomic_write_files, json_text
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
    if as_json:
        click.echo(json.dumps({"iso9283": block}))
        return
    _echo(block)
    if out_dir:
        click.echo(f"wrote     {out_dir}: report.json, report.html")


def _echo(block: dict[str, Any]) -> None:
    """The console table: AP, RP per point, before and after."""
    orient = block["kind"] == "pose"
    for key, name in (
        ("nominal", "nominal robot (before)"),
        ("model", "model (after)"),
    ):
        fig = block.get(key)
        if not fig:
            continue
        click.echo(f"ISO 9283  {name}")
        head = "point  n    AP_P     AP_x     AP_y     AP_z     RP_l  [mm]"
        click.echo(head + ("   AP_a/b/c, RP_a/b/c [deg]" if orient else ""))
        for p in fig["points"]:
            line = f"{p['point']:<5} {p['n']:<3}" + "".join(
                f"{p[k]:9.4f}"
                for k in ("ap_mm", "ap_x_mm", "ap_y_mm", "ap_z_mm", "rp_mm")
            )
            if orient:
                line += "  " + "".join(f"{p[f'ap_{a}_deg']:9.4f}" for a in "abc")
                line += "  " + "".join(f" ±{p[f'rp_{a}_deg']:.4f}" for a in "abc")
            click.echo(line)
        d = fig.get("distance")
        if d:
            click.echo(
                f"distance  {d['pair'][0]}-{d['pair'][1]}: AD_P {d['ad_mm']:.4f} mm  "
                f"RD ±{d['rd_mm']:.4f} mm  ({d['n']} cycles)"
            )
    for note in block["notes"]:
        click.echo(f"note      {note}")
