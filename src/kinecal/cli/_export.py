"""``kinecal export-urdf``: the calibrated kinematic part for the controller (issue 23)."""

from __future__ import annotations

from typing import Any

import click

from kinecal.cli._common import option_table, refuse_unused, targets_option

_FILE = click.Path(dir_okay=False)
_DEFAULT = {"show_default": True}
# (option declarations, settings) of `kinecal export-urdf`, in the order --help lists
# them.
# fmt: off
_OPTIONS: list[Any] = [
    (("--out", "out_path"), {"required": True, "type": _FILE, "help": "calibrated.urdf "
        "(or the robot YAML with --format yaml-dh)."}),
    (("--format", "fmt"), {"type": click.Choice(("urdf", "yaml-dh", "ur-calibration")),
        "default": "urdf", **_DEFAULT, "help": "urdf: root link 'user', joints j1..jN, "
        "tool links. yaml-dh: the calibrated DH table as a robot YAML, loadable as "
        "--robot. ur-calibration: the kinematics.yaml the Universal Robots ROS driver "
        "reads (ur_description joint origins)."}),
    (("--set", "set_label"), {"help": "The set whose user frame is the root (default: "
        "first)."}),
    (("--marker",), {"help": "yaml-dh: the marker that becomes the tool (default: "
        "first)."}),
    (("--coupling",), {"type": click.Choice(("kinematic", "mimic")),
        "default": "kinematic", **_DEFAULT, "help": "URDF joints of a coupled robot: the "
        "kinematic angles (FANUC j3 = J3 + J2), or the controller angles with the "
        "coupling added by mimic joints."}),
    (("--data",), {"type": _FILE, "help": "Poses (measurement CSV) on which to state the "
        "accuracy the compliance terms add (default: the calibration data if the model "
        "names an existing file, else 1000 random poses inside the joint limits)."}),
    (("--names",), {"type": click.Choice(("kinecal", "robot")), "default": "kinecal",
        **_DEFAULT, "help": "urdf without --like: kinecal: root 'user', joints j1..jN, "
        "links link1..N, flange, tool. robot: the robot's own joint names (those of an "
        "imported URDF), links base_link (the root), link_1..link_N, flange, tool0, the "
        "measurement frame 'user' a fixed child of base_link."}),
    (("--like", "like"), {"type": _FILE, "help": "The vendor's URDF of the robot: write "
        "a copy of it with every link, joint, name, mesh, inertial and limit kept and "
        "only the movable joints' origins calibrated (link frames stay the vendor's; "
        "joints take the kinematic angles)."}),
    (("--tool-link",), {"default": "calibrated_tool", **_DEFAULT, "help": "--like: name "
        "of the calibrated tool link (fixed child of the vendor's tip link, the end of "
        "the chain; <name>_<marker> per marker when the model has several)."}),
    (("--user-link",), {"default": None, "help": "--like: add the set's measurement "
        "frame as a new root link of this name (FK from it to the tool link = the "
        "model's tool pose). Default: the vendor's root stays the root."}),
    targets_option,
    (("--force",), {"is_flag": True, "help": "Overwrite --out."}),
]
# fmt: on


@click.command("export-urdf")
@click.argument("model_path", metavar="MODEL.yaml", type=_FILE)
@option_table(_OPTIONS)
def export_urdf(
    model_path: str,
    out_path: str,
    fmt: str,
    set_label: str | None,
    marker: str | None,
    coupling: str,
    data: str | None,
    targets: str | None,
    names: str,
    like: str | None,
    tool_link: str,
    user_link: str | None,
    force: bool,
) -> None:
    """Write the calibrated kinematic part of MODEL.yaml as a URDF (or a DH table).

    The URDF's forward kinematics equal the model with its compliance and transmission
    terms set to zero (to 1e-12 m): root link 'user' (a set's measurement frame), fixed
    joint to 'base' (the robot base), joints j1..jN in radians / metres, links
    link1..linkN (the model's DH frames), 'flange' and 'tool' (or tool_<marker> per
    marker). Compliance and transmission terms cannot live in a URDF: they are listed in
    a comment, with the accuracy lost without them.

    --like VENDOR.urdf writes the vendor's file instead, with only its movable joints'
    origins calibrated and the calibrated tool below its tip link; --format
    ur-calibration writes the Universal Robots driver's kinematics.yaml.
    """
    from pathlib import Path

    from kinecal.io import atomic_write_text, load_model
    from kinecal.workflows import export_model
    from kinecal.workflows._export import labels_text

    if Path(out_path).exists() and not force:  # refuse before the work, not after it
        raise FileExistsError(f"{out_path}: exists; use --force to overwrite it.")
    if names != "kinecal" and (fmt != "urdf" or like is not None):
        raise click.UsageError(
            "--names chooses the names of the plain URDF export; --like keeps the "
            "vendor's names, --format yaml-dh and ur-calibration have none to choose"
        )
    if marker is not None and fmt != "yaml-dh":
        raise click.UsageError(
            "--marker chooses the tool of --format yaml-dh; a URDF holds every marker "
            "(tool_<marker> links)"
        )
    if fmt == "ur-calibration" and (like is not None or coupling != "kinematic"):
        raise click.UsageError(
            "--format ur-calibration does not go with --like or --coupling mimic"
        )
    if like is not None and (fmt != "urdf" or coupling != "kinematic"):
        raise click.UsageError(
            "--like writes a URDF whose joints take the kinematic angles; it does "
            "not go with --format yaml-dh or --coupling mimic"
        )
    why = {} if data else {"targets": "is for --data (sensor data)"}
    why |= {} if like else dict.fromkeys(("tool_link", "user_link"), "is for --like")
    refuse_unused(why | ({"coupling": "is for urdf"} if fmt == "yaml-dh" else {}))
    cal = load_model(model_path)
    for option, label, own in (
        ("--set", set_label, cal.model.spec.sets),
        ("--marker", marker, cal.model.spec.markers),
    ):
        if label is not None and label not in own:
            raise click.BadParameter(
                f"{option[2:]} {label!r} is not in the model {model_path}; expected "
                f"{labels_text(own, option[2:])}",
                param_hint=option,
            )
    ex = export_model(
        cal,
        fmt,
        model_name=model_path,
        set_label=set_label,
        marker=marker,
        coupling=coupling,
        data=data,
        targets=targets,
        names=names,
        like=like,
        tool_link=tool_link,
        user_link=user_link,
    )
    for w in ex.warning_lines(out_path):
        click.echo(w, err=True)
    atomic_write_text(out_path, ex.text, force=force)
    click.echo(f"{ex.robot}: wrote {out_path} {ex.detail}")
