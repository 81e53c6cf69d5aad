"""``kinecal export-urdf``: the calibrated kinematic part for the controller (issue 23)."""

from __future__ import annotations

import click

from kinecal.cli._common import targets_option


@click.command("export-urdf")
@click.argument("model_path", metavar="MODEL.yaml", type=click.Path(dir_okay=False))
@click.option(
    "--out",
    "out_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="calibrated.urdf (or the robot YAML with --format yaml-dh).",
)
@click.option(
    "--format",
    "fmt",
    type=click.Choice(("urdf", "yaml-dh", "ur-calibration")),
    default="urdf",
    show_default=True,
    help="urdf: root link 'user', joints j1..jN, tool links. yaml-dh: the calibrated DH "
    "table as a robot YAML, loadable as --robot. ur-calibration: the kinematics.yaml "
    "the Universal Robots ROS driver reads (ur_description joint origins).",
)
@click.option(
    "--set", "set_label", help="The set whose user frame is the root (default: first)."
)
@click.option(
    "--marker", help="yaml-dh: the marker that becomes the tool (default: first)."
)
@click.option(
    "--coupling",
    type=click.Choice(("kinematic", "mimic")),
    default="kinematic",
    show_default=True,
    help="URDF joints of a coupled robot: the kinematic angles (FANUC j3 = J3 + J2), or "
    "the controller angles with the coupling added by mimic joints.",
)
@click.option(
    "--data",
    type=click.Path(dir_okay=False),
    help="Poses (measurement CSV) on which to state the accuracy the compliance terms "
    "add (default: the calibration data if the model names an existing file, else "
    "1000 random poses inside the joint limits).",
)
@click.option(
    "--names",
    type=click.Choice(("kinecal", "robot")),
    default="kinecal",
    show_default=True,
    help="urdf without --like: kinecal: root 'user', joints j1..jN, links link1..N, "
    "flange, tool. robot: the robot's own joint names (those of an imported URDF), links "
    "base_link (the root), link_1..link_N, flange, tool0, the measurement frame 'user' "
    "a fixed child of base_link.",
)
@click.option(
    "--like",
    "like",
    type=click.Path(dir_okay=False),
    help="The vendor's URDF of the robot: write a copy of it with every link, joint, "
    "name, mesh, inertial and limit kept and only the movable joints' origins "
    "calibrated (link frames stay the vendor's; joints take the kinematic angles).",
)
@click.option(
    "--tool-link",
    default="calibrated_tool",
    show_default=True,
    help="--like: name of the calibrated tool link (fixed child of the vendor's tip "
    "link, the end of the chain; <name>_<marker> per marker when the model has several).",
)
@click.option(
    "--user-link",
    default=None,
    help="--like: add the set's measurement frame as a new root link of this name (FK "
    "from it to the tool link = the model's tool pose). Default: the vendor's root stays "
    "the root.",
)
@targets_option
@click.option("--force", is_flag=True, help="Overwrite --out.")
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

    from kinecal.compensation import (
        check_chain,
        dh_description,
        export_chain,
        geometry_loss,
        has_compliance,
    )
    from kinecal.io import atomic_write_text, load_model, robot_yaml_text, urdf_text

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
    cal = load_model(model_path)
    for option, label, own in (
        ("--set", set_label, cal.model.spec.sets),
        ("--marker", marker, cal.model.spec.markers),
    ):
        if label is not None and label not in own:
            raise click.BadParameter(
                f"{option[2:]} {label!r} is not in the model {model_path}; expected "
                f"one of {_labels(own)}",
                param_hint=option,
            )
    robot = cal.model.robot
    inputs, where, data_lines = _loss_poses(cal, data, targets)
    notes = [
        f"Kinematic part of the calibrated model {Path(model_path).name} "
        f"({robot.name}, model '{cal.model.spec.name}'), written by kinecal export-urdf.",
        "Lengths in metres, angles in radians (URDF).",
    ]
    if has_compliance(cal):
        loss = geometry_loss(cal, inputs)
        lost = (
            f"Without them the prediction moves by {loss.rms * 1e3:.4f} mm RMS, "
            f"{loss.max * 1e3:.4f} mm max over {where}."
        )
        notes += [
            "GEOMETRY ONLY: the model's compliance and transmission terms are not in "
            f"this file (a {'URDF' if fmt == 'urdf' else 'DH table'} cannot hold them):",
            *_compliance_lines(cal),
            lost,
            *data_lines,
            "For the full accuracy, correct the programs with kinecal compensate.",
        ]
        click.echo(
            f"warning: {out_path} holds the geometry only, not the compliance and "
            f"transmission terms: without them the prediction moves by "
            f"{loss.rms * 1e3:.4f} mm RMS, {loss.max * 1e3:.4f} mm max over {where}.",
            err=True,
        )
    rng_q = _random_poses(robot, 256)
    if fmt == "ur-calibration":
        if like is not None or coupling != "kinematic":
            raise click.UsageError(
                "--format ur-calibration does not go with --like or --coupling mimic"
            )
        from kinecal.io._ur_calibration import ur_calibration_text

        notes.append(
            "The origins of ur_description's joints (x y z m, roll pitch yaw rad), as "
            "ur_calibration writes them; base_link is the calibrated robot base (the "
            "tool and the measurement frame are not part of this file)."
        )
        notes.append(
            "The hash is kinecal's, not the controller's: the driver reports that it "
            "differs from the robot's factory calibration."
        )
        text = ur_calibration_text(cal, set_label=set_label, comments=notes)
        atomic_write_text(out_path, text, force=force)
        click.echo(f"{robot.name}: wrote {out_path} (ur-calibration kinematics.yaml)")
        return
    if like is not None:
        if fmt != "urdf" or coupling != "kinematic":
            raise click.UsageError(
                "--like writes a URDF whose joints take the kinematic angles; it does "
                "not go with --format yaml-dh or --coupling mimic"
            )
        from kinecal.io._urdf_like import like_urdf

        notes.append(
            f"A copy of {Path(like).name} with the movable joints' origins calibrated "
            "(everything else as the vendor wrote it); calibrated tool frame: link "
            f"{tool_link!r}."
        )
        if not _identity(robot.coupling):
            notes.append(
                _coupling_note(robot)
                .replace("Joints j1..jN", "The URDF joints")
                .replace(" Coupling 'mimic' writes controller angles instead.", "")
            )
            notes.append(coupling_line(robot))
        res = like_urdf(
            cal,
            like,
            set_label=set_label,
            tool_link=tool_link,
            user_link=user_link,
            comments=notes,
            tip_note=True,
        )
        if res.check_m > 1e-9:  # pragma: no cover - a defect, not a user error
            raise RuntimeError(
                f"export-urdf --like: the file misses the model by {res.check_m:.2e} m."
            )
        if res.mismatch_mm > 0.01:
            click.echo(
                f"warning: {like} describes {robot.name} {res.mismatch_mm:.3f} mm (or "
                "mrad) away from the model's nominal robot (other numbers for the same "
                "robot?): the forward kinematics are exact, the vendor's meshes sit up to "
                "that far from where the calibrated robot has them.",
                err=True,
            )
        atomic_write_text(out_path, res.text, force=force)
        click.echo(
            f"{robot.name}: wrote {out_path} (copy of {like}: joints "
            f"{', '.join(res.joints)}; origins moved by up to {res.moved_mm:.3f} mm, "
            f"{res.turned_deg:.4f} deg; root {res.root!r}, tip {res.tip!r}, tool "
            f"{', '.join(repr(t) for t in res.tips.values())} below it; FK equals the "
            "model to "
            f"{res.check_m * 1e3:.1e} mm)"
        )
        return
    if fmt == "urdf":
        chain = export_chain(cal, set_label=set_label, coupling=coupling)
        if coupling == "kinematic" and not _identity(robot.coupling):
            notes.append(_coupling_note(robot))
            notes.append(coupling_line(robot))
        else:
            notes.append("Joints j1..jN take the controller angles (radians / metres).")
        notes.append(
            "kinecal tip link: flange (the robot's flange, for import-urdf and --robot)."
        )
        known = [j.velocity is not None for j in robot.joints]
        notes.append(
            "Joint limits are the controller's (for a coupled joint in kinematic angles: "
            "the widest range they allow); velocity "
            + (
                "from the robot file"
                if all(known)
                else "1 rad/s (m/s), a placeholder: the robot file states none"
                if not any(known)
                else "from the robot file where it states one, else 1 rad/s (m/s)"
            )
            + "; effort "
            + (
                "from the robot file."
                if all(j.effort is not None for j in robot.joints)
                else "1000 N m (N) where the robot file states none (a placeholder)."
            )
        )
        err = check_chain(cal, chain, set_label, rng_q)
        if err > 1e-9:  # pragma: no cover - a defect, not a user error
            raise RuntimeError(f"export-urdf: the chain misses the model by {err:.2e}.")
        from kinecal.io._urdf_export import (
            joint_rates,
            robot_named_chain,
            stable_splits,
        )

        split = stable_splits(cal, set_label=set_label, coupling=coupling)
        if names == "robot":
            import numpy as np

            named, renamed = robot_named_chain(robot, chain)
            split = frozenset(renamed.get(s, s) for s in split)
            Tb = np.linalg.inv(chain.T_user_base)
            for label, tip in chain.tips.items():
                d = named.fk(rng_q, named.tips[label]) - Tb @ chain.fk(rng_q, tip)
                if np.abs(d).max() > 1e-9:  # pragma: no cover - a defect
                    raise RuntimeError(
                        "export-urdf --names robot: renaming moved a frame."
                    )
            chain = named
            notes = [
                n.replace("Joints j1..jN", "The joints").replace("j1..jN", "the joints")
                for n in notes
            ]
            notes.append(
                "Root base_link = the calibrated robot base; the measurement frame is the "
                "fixed child link 'user'."
            )
        text = urdf_text(
            chain,
            name=f"{robot.name}_calibrated",
            comments=notes,
            split=split,
            rates=joint_rates(robot, chain),
        )
    else:
        desc, T_user_base = dh_description(cal, set_label=set_label, marker=marker)
        from kinecal.geometry import transform_to_euler

        e = transform_to_euler(T_user_base)
        notes = [
            ln.replace("Lengths in metres, angles in radians (URDF).", "")
            for ln in notes
        ]
        notes += [
            "Robot base in the user frame (x, y, z mm; r, w, p deg, Trans Rz Ry Rx): "
            + ", ".join(
                f"{v:.9f}" for v in [*(e[:3] * 1e3), *(e[3:] * 180 / 3.141592653589793)]
            ),
            "The tool is the calibrated frame of marker "
            f"{(marker if marker is not None else cal.model.spec.markers[0])!r}; "
            "flange and last row are nominal.",
        ]
        text = robot_yaml_text(desc, comments=[n for n in notes if n])
        err = _check_yaml(cal, text, T_user_base, set_label, marker, rng_q)
        if err > 1e-9:
            click.echo(
                f"warning: the DH table reproduces the model to {err * 1e3:.2e} mm only "
                "(nearly parallel axes put the common normal far away).",
                err=True,
            )
    atomic_write_text(out_path, text, force=force)
    click.echo(f"{robot.name}: wrote {out_path} ({fmt})")


def _identity(C) -> bool:
    import numpy as np

    return bool(np.array_equal(C, np.eye(C.shape[0])))


def coupling_line(robot) -> str:
    """The machine-readable coupling line of a URDF whose joints take kinematic angles
    (read back by :func:`kinecal.robot.robot_from_urdf`)."""
    import numpy as np

    C = robot.coupling
    terms = [
        f"J{i + 1} += {float(C[i, k])!r} * J{k + 1}"
        for i in range(C.shape[0])
        for k in map(int, np.flatnonzero(C[i]))
        if k != i
    ]
    return "kinecal coupling (theta = C q_ctrl): " + "; ".join(terms)


def _coupling_note(robot) -> str:
    import numpy as np

    terms = []
    C = robot.coupling
    for i in range(C.shape[0]):
        for k in np.flatnonzero(C[i]):
            if k != i:
                terms.append(f"j{i + 1} = J{i + 1} + {C[i, k]:g} * J{k + 1}")
    return (
        "Joints j1..jN take the kinematic angles theta = C q_ctrl (as the ROS-Industrial "
        "URDFs do): "
        + "; ".join(terms)
        + ". Coupling 'mimic' writes controller angles instead."
    )


def _compliance_lines(cal) -> list[str]:
    import numpy as np

    lay = cal.model.layout
    out = []
    for i, ps in enumerate(lay.specs):
        if ps.group in ("ntm", "load", "link") and cal.params[i] != 0.0:
            v = cal.params[i] * ps.unit.to_file
            out.append(f"  {ps.name} = {v:.6g} {ps.unit.file_unit}")
    if cal.reference_payload_kg is not None:
        out.append(f"  (reference payload {cal.reference_payload_kg:g} kg)")
    return out if np.size(out) else ["  (none)"]


def _random_poses(robot, n: int):
    import numpy as np

    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    return np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))


def _loss_poses(cal, data: str | None, targets: str | None):
    """Model inputs on which to state the accuracy lost, a description of them, and
    lines comparing both models with the measurements (when there are any)."""
    from dataclasses import replace
    from pathlib import Path

    from kinecal.compensation import kinematic_params
    from kinecal.errors import CalibError
    from kinecal.io import read_measurements
    from kinecal.models import ModelInputs

    meas = None
    if data is not None:
        meas = cal.align(read_measurements(data, cal.model.robot, targets))
        source = data
    else:  # the calibration data, when the model names a file that reads
        source = cal.info.get("source")
        if isinstance(source, str) and Path(source).is_file():
            try:
                meas = cal.align(read_measurements(source, cal.model.robot, targets))
            except CalibError:
                meas = None
    if meas is None:
        q = _random_poses(cal.model.robot, 1000)
        return ModelInputs.make(q), "1000 random poses inside the joint limits", []
    inputs = meas.model_inputs(cal.reference_payload_kg)
    full = cal.metrics(meas)
    geo = replace(cal, params=kinematic_params(cal)).metrics(meas)
    lines = [
        f"Against the measurements of {Path(source).name}: full model "
        f"{full.rms_mm:.4f} mm RMS, kinematic part {geo.rms_mm:.4f} mm RMS."
    ]
    return inputs, f"the {meas.n} poses of {Path(source).name}", lines


def _check_yaml(cal, text, T_user_base, set_label, marker, q) -> float:
    """Largest distance [m] between the written DH table (read back) and the model."""
    import numpy as np

    from kinecal import _yaml as yaml
    from kinecal.compensation import kinematic_params
    from kinecal.models import ModelInputs
    from kinecal.robot import robot_from_dict

    again = robot_from_dict(yaml.load(text), source="<export>")
    spec = cal.model.spec
    s = 0 if set_label is None else spec.sets.index(set_label)
    m = 0 if marker is None else spec.markers.index(marker)
    N = q.shape[0]
    inp = ModelInputs.make(q, set_index=np.full(N, s), marker_index=np.full(N, m))
    out = cal.model.evaluate(kinematic_params(cal), inp)
    T = T_user_base @ again.fk_tool(q)
    return float(np.abs(T[:, :3, 3] - out.p_user).max())


def _labels(own: tuple[str, ...]) -> str:
    """A model's set or marker labels for a message (the default one is '')."""
    return ", ".join(repr(x) if x else "'' (the default)" for x in own)
