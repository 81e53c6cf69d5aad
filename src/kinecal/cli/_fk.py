"""``kinecal fk`` and ``kinecal robots``."""

from __future__ import annotations

import json

import click


@click.command()
@click.option(
    "--robot",
    "robot_name",
    metavar="NAME|FILE",
    help="Built-in robot name (see `kinecal robots`) or robot YAML file.",
)
@click.option(
    "--model",
    "model_path",
    type=click.Path(dir_okay=False),
    help="A calibrated model.yaml instead of --robot: the calibrated poses.",
)
@click.option(
    "--payload-kg",
    type=float,
    help="With --model: payload at the tool [kg] (default: the calibration's).",
)
@click.option(
    "--set", "set_label", help="With --model: the user frame (default: first)."
)
@click.option("--marker", help="With --model: the tool marker (default: first).")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option(
    "--ignore-limits",
    is_flag=True,
    help="Compute poses beyond the joint limits too (refused otherwise: the robot "
    "cannot take them).",
)
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
    import numpy as np

    from kinecal.errors import DataError

    if (robot_name is None) == (model_path is None):
        raise click.UsageError("give one of --robot NAME|FILE and --model MODEL.yaml.")
    if model_path is None and (payload_kg, set_label, marker) != (None, None, None):
        raise click.UsageError("--payload-kg, --set and --marker need --model.")
    if model_path is not None:
        from kinecal.io import load_model

        cal = load_model(model_path)
        robot = cal.model.robot
    else:
        from kinecal.robot import load_robot

        assert robot_name is not None
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
    _check_joints(robot, joints, q, ignore_limits)
    if model_path is not None:
        out = _model_fk(cal, q, payload_kg, set_label, marker)
        if as_json:
            click.echo(json.dumps(out))
            return
        click.echo(f"model   {model_path} ({robot.name})")
        for title, d in (("with all terms", out), ("kinematic part", out["kinematic"])):
            click.echo(f"{title}:")
            _echo_pose("flange", "(base)", d["flange_mm"], d["wpr_deg"])
            _echo_pose("tool", "(user)", d["tool_mm"], d["tool_wpr_deg"])
        return
    T = robot.fk_flange(q)
    xyz, wpr = _pose_mm_deg(T)
    if as_json:
        click.echo(json.dumps({"flange_mm": xyz, "wpr_deg": wpr}))
        return
    click.echo(f"robot   {robot.name}")
    click.echo("flange  x {:.4f}  y {:.4f}  z {:.4f}  mm".format(*xyz))
    click.echo("        w {:.4f}  p {:.4f}  r {:.4f}  deg".format(*wpr))


def _check_joints(robot, joints, q, ignore_limits: bool) -> None:
    """Finite joint values, inside the joint limits unless ``ignore_limits``."""
    import numpy as np

    from kinecal.errors import DataError

    for k, (v, j) in enumerate(zip(joints, robot.joints)):
        unit = "mm" if j.kind == "prismatic" else "deg"
        if not np.isfinite(v):
            raise DataError(f"J{k + 1}: expected a finite value in {unit}; got {v}.")
        lo, hi = j.limits
        if ignore_limits or lo - 1e-12 <= q[k] <= hi + 1e-12:
            continue
        f = 1e3 if j.kind == "prismatic" else 180.0 / np.pi
        raise DataError(
            f"J{k + 1}: {v:g} {unit} is beyond the joint limits [{lo * f:g}, "
            f"{hi * f:g}] {unit} of {robot.name}; expected a value inside them "
            "(--ignore-limits computes the pose anyway)."
        )


def _echo_pose(what: str, frame: str, xyz: list[float], wpr: list[float]) -> None:
    click.echo(f"  {what:7s}{frame} x {xyz[0]:.4f}  y {xyz[1]:.4f}  z {xyz[2]:.4f}  mm")
    click.echo(f"                 w {wpr[0]:.4f}  p {wpr[1]:.4f}  r {wpr[2]:.4f}  deg")


def _pose_mm_deg(T) -> tuple[list[float], list[float]]:
    import numpy as np

    from kinecal.geometry import matrix_to_wpr

    return (T[:3, 3] * 1e3).tolist(), np.degrees(matrix_to_wpr(T[:3, :3])).tolist()


def _model_fk(cal, q, payload_kg, set_label, marker) -> dict:
    """The calibrated flange (robot base) and tool (user frame), with and without the
    compliance terms, as the JSON object of ``kinecal fk --model``."""
    import numpy as np

    from kinecal.compensation import flange_offset, kinematic_params, robot_base_offset
    from kinecal.errors import DataError
    from kinecal.models import ModelInputs

    spec = cal.model.spec
    idx = []
    for what, label, own in (
        ("set", set_label, spec.sets),
        ("marker", marker, spec.markers),
    ):
        if label is not None and label not in own:
            raise DataError(
                f"--{what}: {what} {label!r} is not in the model; expected one of "
                f"{_labels(own)}."
            )
        idx.append(0 if label is None else own.index(label))
    scale = 1.0
    if payload_kg is not None:
        if not payload_kg >= 0:
            raise DataError(f"--payload-kg must be >= 0; got {payload_kg}.")
        ref = cal.reference_payload_kg
        if ref is None:
            if spec.load:
                raise DataError(
                    "the model has no reference payload (its compliance is per unit of "
                    "the calibration's load): --payload-kg cannot be used."
                )
        else:
            scale = payload_kg / ref
    inp = ModelInputs.make(
        q[None], set_index=[idx[0]], marker_index=[idx[1]], load_scale=[scale]
    )
    P0 = robot_base_offset(cal.model.robot)
    F = flange_offset(cal.model.robot)
    out = {}
    for key, x in (("full", cal.params), ("kinematic", kinematic_params(cal))):
        R, o = cal.model.flange_frames(x, inp)
        T_fl = np.eye(4)
        T_fl[:3, :3], T_fl[:3, 3] = R[0], o[0]
        flange = _pose_mm_deg(P0 @ T_fl @ F)
        ev = cal.model.evaluate(x, inp, orientation=True)
        T_tool = np.eye(4)
        T_tool[:3, :3], T_tool[:3, 3] = ev.R_user_cam[0], ev.p_user[0]
        tool = _pose_mm_deg(T_tool)
        out[key] = {
            "flange_mm": flange[0],
            "wpr_deg": flange[1],
            "tool_mm": tool[0],
            "tool_wpr_deg": tool[1],
        }
    return {
        **out["full"],
        "kinematic": out["kinematic"],
        "payload_kg": payload_kg
        if payload_kg is not None
        else cal.reference_payload_kg,
        "set": spec.sets[idx[0]],
        "marker": spec.markers[idx[1]],
    }


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

    The DH table reproduces the URDF's forward kinematics exactly. The links' inertials
    become link_masses (mass and centre of mass of each body), the layout of the general
    link self-weight model that the rfcm, full and auto models then use. Edit the YAML
    to add couplings, gravity (default: along -z of the base link), the payload or
    priors.
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
    chain = robot.source.rsplit("(URDF ", 1)[-1].rstrip(")")
    coupled = (
        ""
        if np.array_equal(robot.coupling, np.eye(robot.n_joints))
        else (", coupled by mimic joints")
    )
    click.echo(f"{robot.name}: {robot.n_joints} joints ({chain}{coupled}) -> {out}")
    click.echo(_self_weight_summary(robot))


def _self_weight_summary(robot) -> str:
    """One line on the imported link masses and the joints their weight loads."""
    if not robot.link_bodies:
        return (
            "link masses: none in the URDF (no <inertial>); the models have no link "
            "self-weight terms (add link_masses or self_weight to the YAML)"
        )
    import numpy as np

    from kinecal.simulation import gravity_torques, random_joint_poses

    q = random_joint_poses(robot, 200, np.random.default_rng(0))
    tau = np.abs(gravity_torques(robot, q)).max(axis=0)
    loaded = [robot.joint_names[j] for j in range(robot.n_joints) if tau[j] > 1e-9]
    total = sum(b.mass for b in robot.link_masses)
    return (
        f"link masses: {len(robot.link_bodies)} bodies, {total:.3g} kg; gravity "
        f"loads joints {', '.join(loaded) or 'none'}"
    )


def _labels(own: tuple[str, ...]) -> str:
    """A model's set or marker labels for a message (the default one is '')."""
    return ", ".join(repr(x) if x else "'' (the default)" for x in own)
