"""``kinecal fk`` and ``kinecal robots``."""

from __future__ import annotations

import json

import click


@click.command()
@click.option(
    "--robot",
    "robot_name",
    required=True,
    metavar="NAME|FILE",
    help="Built-in robot name (see `kinecal robots`) or robot YAML file.",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.argument("joints", nargs=-1, type=float, required=True)
def fk(robot_name: str, as_json: bool, joints: tuple[float, ...]) -> None:
    """Nominal flange pose from controller joint angles J1 ... JN [deg; mm if prismatic].

    Prints the physical flange position [mm] and FANUC W, P, R [deg] in the robot base
    frame (FANUC: World, at J2 height). Put negative angles after `--`:

        kinecal fk --robot fanuc-lrmate200id --json -- 30 20 -10 45 -60 90
    """
    import numpy as np

    from kinecal.errors import DataError
    from kinecal.geometry import matrix_to_wpr
    from kinecal.robot import load_robot

    robot = load_robot(robot_name)
    if len(joints) != robot.n_joints:
        raise DataError(
            f"{robot.name} has {robot.n_joints} joints; got {len(joints)} joint values."
        )
    q = np.array(
        [
            v * (1e-3 if j.kind == "prismatic" else np.pi / 180.0)
            for v, j in zip(joints, robot.joints)
        ]
    )
    T = robot.fk_flange(q)
    xyz = (T[:3, 3] * 1e3).tolist()
    wpr = np.degrees(matrix_to_wpr(T[:3, :3])).tolist()
    if as_json:
        click.echo(json.dumps({"flange_mm": xyz, "wpr_deg": wpr}))
        return
    click.echo(f"robot   {robot.name}")
    click.echo("flange  x {:.4f}  y {:.4f}  z {:.4f}  mm".format(*xyz))
    click.echo("        w {:.4f}  p {:.4f}  r {:.4f}  deg".format(*wpr))


@click.command()
def robots() -> None:
    """List the built-in robots."""
    from kinecal.robot import builtin_robot_names, load_robot

    for name in builtin_robot_names():
        r = load_robot(name)
        click.echo(f"{name:24s} {r.n_joints} joints  {r.convention:3s}  {r.source}")
