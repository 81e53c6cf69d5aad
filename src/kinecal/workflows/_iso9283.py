"""The ISO 9283 workflows of ``kinecal plan --iso9283`` (the pose test program, compensated
with a calibrated model if given) and ``kinecal evaluate --iso9283`` (AP, RP, AD, RD of a
measured test). File columns (docs/iso9283.md): the plan's joint columns, ``iso_point``
(P1..P5), ``iso_cycle`` (1..n), ``cmd_x_mm, cmd_y_mm, cmd_z_mm`` (command position in the
robot base frame) and ``cmd_a_deg, cmd_b_deg, cmd_c_deg`` (command orientation)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.errors import DataError
from kinecal.iso9283 import IsoEvaluation, IsoPlan
from kinecal.measurement import CalibratedModel, Measurements
from kinecal.robot import RobotDescription

__all__ = ["IsoTestProgram", "IsoTestResult", "evaluate_iso_test", "iso_test_program"]

POINT_COLUMN, CYCLE_COLUMN = "iso_point", "iso_cycle"
# The command pose of each row a plan writes beside them (for the operator).
CMD_COLUMNS = (
    "cmd_x_mm",
    "cmd_y_mm",
    "cmd_z_mm",
    "cmd_a_deg",
    "cmd_b_deg",
    "cmd_c_deg",
)
# What a plan's rows carry besides the joints (``simulate --plan`` keeps them): the
# point and cycle under the plan's names or the plain ones, and the command pose.
PLAN_COLUMNS = (POINT_COLUMN, CYCLE_COLUMN, "point", "cycle", *CMD_COLUMNS)

Progress = Callable[[str, str], None]


def _quiet(stage: str, detail: str) -> None:
    """No progress display."""


@dataclass(frozen=True)
class IsoTestProgram:
    """What :func:`iso_test_program` made.

    Attributes
    ----------
    plan : the cube, its points, the joints of every row (compensated if a model was
        given).
    lines : PLAN.csv's lines.
    report : PLAN.report.json's content.
    """

    plan: IsoPlan = field(repr=False)
    lines: list[str] = field(repr=False)
    report: dict[str, Any] = field(repr=False)
    joint_factors: np.ndarray = field(repr=False)
    compensated_with: str | None = None

    def csv_text(self) -> str:
        """PLAN.csv."""
        return "\n".join(self.lines) + "\n"

    def summary_lines(self) -> list[str]:
        """What ``kinecal plan --iso9283`` prints before its ``wrote`` line."""
        from kinecal.iso9283 import POINT_LABELS, VISIT_ORDER

        pl, f = self.plan, self.joint_factors
        cube, pts_mm = pl.cube, pl.cube.points * 1e3
        out = [
            f"cube      edge {cube.edge * 1e3:.1f} mm, centre "
            + ", ".join(f"{v:.1f}" for v in cube.centre * 1e3)
            + f" mm (robot base), plane {cube.plane}"
        ]
        for i, lab in enumerate(POINT_LABELS):
            out.append(
                f"{lab}        "
                + ", ".join(f"{v:8.2f}" for v in pts_mm[i])
                + " mm   joints "
                + " ".join(f"{v:.2f}" for v in pl.q_points[i] * f)
            )
        out.append(
            f"program   {pl.cycles} cycles of {' -> '.join(VISIT_ORDER)}: "
            f"{len(self.lines) - 1} rows"
        )
        if self.compensated_with is not None:
            out.append(
                f"joints    compensated with {self.compensated_with} (the points "
                "through its user frame; evaluate --iso9283 gives the accuracy after "
                "compensation)"
            )
        return out


def iso_test_program(
    robot: RobotDescription,
    *,
    cal: CalibratedModel | None = None,
    edge_mm: float | None = None,
    centre_mm: tuple[float, float, float] | None = None,
    R_base_tool: np.ndarray | None = None,
    cycles: int = 30,
    plane: str = "C1-C2-C7-C8",
    seed: int = 0,
    T_flange_tool: np.ndarray | None = None,
    model_name: str = "the model",
    progress: Progress | None = None,
) -> IsoTestProgram:
    """The ISO 9283 pose test program of ``robot``, as ``kinecal plan --iso9283``
    writes it: the cube (edge and centre [mm] in the robot base frame, or the largest
    reachable one), its test points P1-P5 in ``cycles`` cycles, joints by the nominal
    IK, compensated with ``cal`` (``model_name``: its file) when given.

    Returns
    -------
    IsoTestProgram
        The plan, PLAN.csv's lines and report.json's content.
    """
    from kinecal.iso9283 import compensated_plan, plan_iso9283
    from kinecal.workflows._args import need_robot

    need_robot(robot)
    say = progress or _quiet
    edge = None if edge_mm is None else edge_mm * 1e-3
    centre = None if centre_mm is None else np.array(centre_mm) * 1e-3
    say("iso9283", "placing the cube" if edge is None else "checking the cube")
    pl = plan_iso9283(
        robot,
        edge=edge,
        centre=centre,
        R_base_tool=R_base_tool,
        cycles=cycles,
        plane=plane,
        seed=seed,
        T_flange_tool=T_flange_tool,
    )
    if cal is not None:
        say("iso9283", f"compensating the program with {model_name}")
        pl = compensated_plan(pl, cal)
    lines, joint_cols, f = _plan_lines(robot, pl)
    comp = model_name if cal is not None else None
    doc = _plan_doc(robot, pl, joint_cols, f, comp)
    return IsoTestProgram(pl, lines, doc, f, comp)


def _plan_lines(
    robot: RobotDescription, pl: IsoPlan
) -> tuple[list[str], list[str], np.ndarray]:
    """The program's CSV lines, its joint columns and their factors from SI."""
    from kinecal.iso9283 import POINT_LABELS, orientation_abc

    joint_cols = [
        f"j{k + 1}_mm" if j.kind == "prismatic" else f"j{k + 1}_deg"
        for k, j in enumerate(robot.joints)
    ]
    f = np.array([1e3 if j.kind == "prismatic" else 180 / np.pi for j in robot.joints])
    abc = np.degrees(orientation_abc(pl.R_base_tool))
    lines = [",".join([*joint_cols, POINT_COLUMN, CYCLE_COLUMN, *CMD_COLUMNS])]
    pts_mm = pl.cube.points * 1e3
    for q, k, c in zip(pl.q_ctrl * f, pl.point_index, pl.cycle):
        cells = [f"{v:.6f}" for v in q] + [POINT_LABELS[k], str(c)]
        cells += [f"{v:.4f}" for v in pts_mm[k]] + [f"{v:.6f}" for v in abc]
        lines.append(",".join(cells))
    return lines, joint_cols, f


def _plan_doc(
    robot: RobotDescription,
    pl: IsoPlan,
    joint_cols: list[str],
    f: np.ndarray,
    compensated_with: str | None,
) -> dict[str, Any]:
    """The program's report.json."""
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
            "compensated_with": compensated_with,
        }
    }
    return doc


@dataclass(frozen=True)
class IsoTestResult:
    """What :func:`evaluate_iso_test` found: ``evaluation`` (AP, RP per point, AD,
    RD; with the model and the nominal robot) and ``block``, its report.json block."""

    evaluation: IsoEvaluation = field(repr=False)
    block: dict[str, Any] = field(repr=False)

    def table_lines(self) -> list[str]:
        """The console table of ``kinecal evaluate --iso9283``: AP, RP per point,
        before and after."""
        block = self.block
        orient = block["kind"] == "pose"
        out = []
        for key, name in (
            ("nominal", "nominal robot (before)"),
            ("model", "model (after)"),
        ):
            fig = block.get(key)
            if not fig:
                continue
            out.append(f"ISO 9283  {name}")
            head = "point  n    AP_P     AP_x     AP_y     AP_z     RP_l  [mm]"
            out.append(head + ("   AP_a/b/c, RP_a/b/c [deg]" if orient else ""))
            for p in fig["points"]:
                line = f"{p['point']:<5} {p['n']:<3}" + "".join(
                    f"{p[k]:9.4f}"
                    for k in ("ap_mm", "ap_x_mm", "ap_y_mm", "ap_z_mm", "rp_mm")
                )
                if orient:
                    line += "  " + "".join(f"{p[f'ap_{a}_deg']:9.4f}" for a in "abc")
                    line += "  " + "".join(f" ±{p[f'rp_{a}_deg']:.4f}" for a in "abc")
                out.append(line)
            d = fig.get("distance")
            if d:
                out.append(
                    f"distance  {d['pair'][0]}-{d['pair'][1]}: AD_P {d['ad_mm']:.4f} "
                    f"mm  RD ±{d['rd_mm']:.4f} mm  ({d['n']} cycles)"
                )
                if "ad_a_deg" in d:
                    out.append(
                        "          AD_a,b,c "
                        + " ".join(f"{d[f'ad_{a}_deg']:.4f}" for a in "abc")
                        + " deg  RD_a,b,c ±"
                        + " ±".join(f"{d[f'rd_{a}_deg']:.4f}" for a in "abc")
                        + " deg"
                    )
        return out + [f"note      {note}" for note in block["notes"]]


def evaluate_iso_test(
    cal: CalibratedModel,
    meas: Measurements,
    data: str | Path,
    *,
    refit: tuple[str, ...] = (),
) -> IsoTestResult:
    """The ISO 9283 figures of a measured pose test, as ``kinecal evaluate --iso9283``
    finds them: ``meas`` read from ``data``, whose ``iso_point`` and ``iso_cycle``
    columns (or ``point``, ``cycle``) say the test point and cycle of every row.

    Raises
    ------
    DataError
        No point or cycle column, or a cycle that is not a number.
    """
    from kinecal.iso9283 import evaluate_iso9283
    from kinecal.workflows._args import need_measurements, need_model

    need_model(cal)
    need_measurements(meas, cal.model.robot.n_joints)

    point, cycle = _labels(str(data), meas.rows)
    iso = evaluate_iso9283(cal, meas, point, cycle, refit=refit)
    return IsoTestResult(iso, iso.as_dict())


def _labels(data: str, rows: Any) -> tuple[np.ndarray, np.ndarray]:
    """``iso_point`` and ``iso_cycle`` of the data rows (by file line)."""
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
