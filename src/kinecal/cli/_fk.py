"""``kinecal fk`` and ``kinecal robots``."""

from __future__ import annotations

import json
from typing import Any

import click

from kinecal.cli._common import option_table

# fmt: off
_FK_OPTIONS: list[Any] = [
    (("--robot", "robot_name"), {"metavar": "NAME|FILE", "help": "Built-in robot name "
        "(see `kinecal robots`) or robot YAML file."}),
    (("--model", "model_path"), {"type": click.Path(dir_okay=False), "help": "A "
        "calibrated model.yaml instead of --robot: the calibrated poses."}),
    (("--payload-kg",), {"type": float, "help": "With --model: payload at the tool [kg] "
        "(default: the calibration's)."}),
    (("--set", "set_label"), {"help": "With --model: the user frame (default: first)."}),
    (("--marker",), {"help": "With --model: the tool marker (default: first)."}),
    (("--json", "as_json"), {"is_flag": True, "help": "Print one JSON object."}),
    (("--ignore-limits",), {"is_flag": True, "help": "Compute poses beyond the joint "
        "limits too (refused otherwise: the robot cannot take them)."}),
]
# fmt: on


@click.command()
@option_table(_FK_OPTIONS)
@click.argument("joints", nargs=-1, type=float, required=True)
def fk(
    robot_name: str | None,
    model_path: str | None,
    payload_kg: float | None,
    set_label: str | None,
    marker: str | None,
    as_json: bool,
    ignore_limits: bool,
    joints: tuple[float, ...],
) -> None:
    """Flange pose from controller joint angles J1 ... JN [deg; mm if prismatic].

    With --robot: the nominal physical flange [mm] and FANUC W, P, R [deg] in the robot
    base frame (FANUC: World, at J2 height). With --model: the calibrated flange in the
    robot base frame and the tool point (cam origin) in the user frame, with every term
    of the model and, under "kinematic", without the compliance and transmission terms
    (what `kinecal export-urdf` writes). Put negative angles after `--`:

        kinecal fk --robot fanuc-lrmate200id --json -- 30 20 -10 45 -60 90
    """
    from kinecal.workflows import forward_pose

    if (robot_name is None) == (model_path is None):
        raise click.UsageError("give one of --robot NAME|FILE and --model MODEL.yaml.")
    if model_path is None and (payload_kg, set_label, marker) != (None, None, None):
        raise click.UsageError("--payload-kg, --set and --marker need --model.")
    if model_path is not None:
        from kinecal.io import load_model

        source: Any = load_model(model_path)
    else:
        from kinecal.robot import load_robot

        assert robot_name is not None
        source = load_robot(robot_name)
    pose = forward_pose(
        source,
        joints,
        payload_kg=payload_kg,
        set_label=set_label,
        marker=marker,
        ignore_limits=ignore_limits,
    )
    if as_json:
        click.echo(json.dumps(pose.as_dict()))
        return
    click.echo("\n".join(pose.lines(model_path)))


@click.command()
def robots() -> None:
    """List the built-in robots."""
    from kinecal.robot import builtin_robot_names, load_robot

    for name in builtin_robot_names():
        r = load_robot(name)
        click.echo(f"{name:24s} {r.n_joints} joints  {r.convention:3s}  {r.source}")


@click.command("import-urdf")
@click.argument("urdf", type=click.Path(exists=True, dir_okay=False))
@option_table([
    (("--base",), {"help": "Base link (default: the root link)."}),
    (("--tip",), {"help": "Tip link, the physical flange (default: end of the chain)."}),
    (("--name",), {"help": "Robot name (default: the URDF's)."}),
    (("--out",), {"required": True, "type": click.Path(dir_okay=False),
        "help": "Robot YAML."}),
    (("--force",), {"is_flag": True, "help": "Overwrite --out."}),
])  # fmt: skip
def import_urdf(
    urdf: str,
    base: str | None,
    tip: str | None,
    name: str | None,
    out: str,
    force: bool,
) -> None:
    """Write a robot YAML (standard DH, mm, deg) for the serial chain of a URDF.

    The DH table reproduces the URDF's forward kinematics exactly. The links' inertials
    become link_masses (mass and centre of mass of each body), the layout of the general
    link self-weight model that the rfcm, full and auto models then use. Edit the YAML
    to add couplings, gravity (default: -z of the root link, a mount's world), the
    payload or priors.
    """

    from kinecal.io import atomic_write_text
    from kinecal.workflows import import_urdf_robot

    imp = import_urdf_robot(urdf, base=base, tip=tip, name=name)
    atomic_write_text(out, imp.text, force=force)
    robot = imp.robot
    coupled = ", coupled by mimic joints" if imp.coupled else ""
    click.echo(f"{robot.name}: {robot.n_joints} joints ({imp.chain}{coupled}) -> {out}")
    click.echo(imp.self_weight)
