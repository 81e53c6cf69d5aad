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


@click.command("import-urdf")
@click.argument("urdf", type=click.Path(exists=True, dir_okay=False))
@click.option("--base", help="Base link (default: the root link).")
@click.option(
    "--tip", help="Tip link, the physical flange (default: end of the chain)."
)
@click.option("--name", help="Robot name (default: the URDF's).")
@click.option(
    "--out", required=True, type=click.Path(dir_okay=False), help="Robot YAML."
)
@click.option("--force", is_flag=True, help="Overwrite --out.")
def import_urdf(
    urdf: str,
    base: str | None,
    tip: str | None,
    name: str | None,
    out: str,
    force: bool,
) -> None:
    """Write a robot YAML (standard DH, mm, deg) for the serial chain of a URDF.

    The DH table reproduces the URDF's forward kinematics exactly; edit the YAML to add
    couplings, gravity, the link self-weight layout or priors.
    """
    import numpy as np

    from kinecal import _yaml as yaml
    from kinecal.io import atomic_write_text
    from kinecal.robot import dump_robot, robot_from_dict, robot_from_urdf

    robot = robot_from_urdf(urdf, base=base, tip=tip, name=name)
    doc = dump_robot(robot)
    # Check the written document: it must load and give the same flange poses.
    again = robot_from_dict(yaml.load(yaml.dump(doc)), source=out)
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (16, robot.n_joints))
    err = float(np.abs(again.fk_flange(q) - robot.fk_flange(q)).max())
    if err > 1e-9:  # pragma: no cover - a defect, not a user error
        raise RuntimeError(
            f"import-urdf: the YAML does not reproduce the URDF ({err})."
        )
    header = f"# Imported from {urdf} by kinecal import-urdf ({robot.source}).\n"
    atomic_write_text(out, header + yaml.dump(doc, sort_keys=False), force=force)
    click.echo(f"{robot.name}: {robot.n_joints} joints -> {out}")
