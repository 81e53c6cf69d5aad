"""The export workflow of ``kinecal export-urdf``: the calibrated kinematic part of a
model as a URDF (plain, robot-named or a calibrated copy of the vendor's), a DH table
(robot YAML) or the Universal Robots driver's ``kinematics.yaml``; with the accuracy the
compliance and transmission terms add, which no such file can hold.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.measurement import CalibratedModel
from kinecal.robot import RobotDescription

__all__ = ["ModelExport", "coupling_line", "export_model", "labels_text"]

EXPORT_FORMATS = ("urdf", "yaml-dh", "ur-calibration")


@dataclass(frozen=True)
class ModelExport:
    """What :func:`export_model` wrote into ``text``.

    Attributes
    ----------
    text : the file's content.
    fmt : ``urdf``, ``yaml-dh`` or ``ur-calibration``.
    robot : the robot's name.
    detail : what the file is, for the command's ``wrote`` line, e.g. ``(urdf)``.
    loss_rms_mm, loss_max_mm : how far the prediction moves without the compliance and
        transmission terms (None: the model has none).
    loss_where : the poses those figures are over.
    warnings : further findings (a vendor URDF far from the nominal robot, a DH table
        that reproduces the model only roughly).
    """

    text: str
    fmt: str
    robot: str
    detail: str
    loss_rms_mm: float | None = None
    loss_max_mm: float | None = None
    loss_where: str = ""
    warnings: tuple[str, ...] = ()

    def warning_lines(self, path: str) -> list[str]:
        """The warnings ``kinecal export-urdf`` prints for the file ``path``: what the
        file leaves out, then the others."""
        out = []
        if self.loss_rms_mm is not None:
            out.append(
                f"warning: {path} holds the geometry only, not the compliance and "
                f"transmission terms: without them the prediction moves by "
                f"{self.loss_rms_mm:.4f} mm RMS, {self.loss_max_mm:.4f} mm max over "
                f"{self.loss_where}."
            )
        return out + [f"warning: {w}" for w in self.warnings]


def export_model(
    cal: CalibratedModel,
    fmt: str = "urdf",
    *,
    model_name: str = "model.yaml",
    set_label: str | None = None,
    marker: str | None = None,
    coupling: str = "kinematic",
    data: str | None = None,
    targets: str | None = None,
    names: str = "kinecal",
    like: str | None = None,
    tool_link: str = "calibrated_tool",
    user_link: str | None = None,
) -> ModelExport:
    """The calibrated kinematic part of ``cal`` as ``kinecal export-urdf`` writes it.

    Parameters
    ----------
    cal : the calibrated model.
    fmt : ``urdf``, ``yaml-dh`` or ``ur-calibration``.
    model_name : the model file's name, for the file's comments.
    set_label, marker : the set whose user frame is the root, the marker that becomes
        the tool (yaml-dh); default the first.
    coupling : ``kinematic`` (URDF joints take the kinematic angles) or ``mimic``.
    data, targets : measurements on which to state the accuracy the compliance terms
        add (default: the calibration's data when the model names an existing file,
        else 1000 random poses inside the joint limits).
    names : ``kinecal`` or ``robot`` (the robot's own joint names; plain URDF only).
    like : a vendor URDF of the robot: a copy of it with the joint origins calibrated.
    tool_link, user_link : with ``like``, the calibrated tool link's name and an optional
        new root link for the measurement frame.

    Returns
    -------
    ModelExport
        The file's text, the accuracy lost and the warnings.

    Examples
    --------
    >>> from kinecal.io import load_model                          # doctest: +SKIP
    >>> ex = export_model(load_model("cal/model.yaml"), "urdf")
    >>> Path("calibrated.urdf").write_text(ex.text)
    """
    from kinecal.compensation import geometry_loss, has_compliance
    from kinecal.workflows._args import choice, need_model

    need_model(cal)
    choice(fmt, ("urdf", "yaml-dh", "ur-calibration"), "fmt")
    choice(names, ("kinecal", "robot"), "names")
    robot = cal.model.robot
    inputs, where, data_lines = _loss_poses(cal, data, targets)
    notes = [
        f"Kinematic part of the calibrated model {Path(model_name).name} "
        f"({robot.name}, model '{cal.model.spec.name}'), written by kinecal export-urdf.",
        "Lengths in metres, angles in radians (URDF).",
    ]
    rms = mx = None
    if has_compliance(cal):
        loss = geometry_loss(cal, inputs)
        rms, mx = loss.rms * 1e3, loss.max * 1e3
        notes += [
            "GEOMETRY ONLY: the model's compliance and transmission terms are not in "
            f"this file (a {'URDF' if fmt == 'urdf' else 'DH table'} cannot hold them):",
            *_compliance_lines(cal),
            f"Without them the prediction moves by {rms:.4f} mm RMS, "
            f"{mx:.4f} mm max over {where}.",
            *data_lines,
            "For the full accuracy, correct the programs with kinecal compensate.",
        ]
    lost = _Loss(rms, mx, where)
    if fmt == "ur-calibration":
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
        return lost.result(text, fmt, robot, "(ur-calibration kinematics.yaml)")
    if like is not None:
        return _like(cal, like, notes, set_label, tool_link, user_link, lost)
    warnings: list[str] = []
    if fmt == "urdf":
        text = _urdf_text(cal, notes, set_label, coupling, names)
    else:
        text = _dh_text(cal, notes, set_label, marker, warnings)
    return lost.result(text, fmt, robot, f"({fmt})", warnings)


@dataclass(frozen=True)
class _Loss:
    rms_mm: float | None
    max_mm: float | None
    where: str

    def result(
        self,
        text: str,
        fmt: str,
        robot: RobotDescription,
        detail: str,
        warnings: list[str] | None = None,
    ) -> ModelExport:
        return ModelExport(
            text, fmt, robot.name, detail, self.rms_mm, self.max_mm, self.where,
            tuple(warnings or ()),
        )  # fmt: skip


def _like(
    cal: CalibratedModel,
    like: str,
    notes: list[str],
    set_label: str | None,
    tool_link: str,
    user_link: str | None,
    lost: _Loss,
) -> ModelExport:
    """A copy of the vendor's URDF ``like`` with the movable joints' origins calibrated."""
    from kinecal.io._urdf_like import like_urdf

    robot = cal.model.robot
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
    warnings = []
    if res.mismatch_mm > 0.01:
        warnings.append(
            f"{like} describes {robot.name} {res.mismatch_mm:.3f} mm (or "
            "mrad) away from the model's nominal robot (other numbers for the same "
            "robot?): the forward kinematics are exact, the vendor's meshes sit up to "
            "that far from where the calibrated robot has them."
        )
    detail = (
        f"(copy of {like}: joints "
        f"{', '.join(res.joints)}; origins moved by up to {res.moved_mm:.3f} mm, "
        f"{res.turned_deg:.4f} deg; root {res.root!r}, tip {res.tip!r}, tool "
        f"{', '.join(repr(t) for t in res.tips.values())} below it; FK equals the "
        "model to "
        f"{res.check_m * 1e3:.1e} mm)"
    )
    return lost.result(res.text, "urdf", robot, detail, warnings)


def _urdf_text(
    cal: CalibratedModel,
    notes: list[str],
    set_label: str | None,
    coupling: str,
    names: str,
) -> str:
    """The plain URDF export (kinecal's or the robot's own names)."""
    from kinecal.compensation import check_chain, export_chain
    from kinecal.io import urdf_text
    from kinecal.io._urdf_export import joint_rates, robot_named_chain, stable_splits

    robot = cal.model.robot
    rng_q = _random_poses(robot, 256)
    chain = export_chain(cal, set_label=set_label, coupling=coupling)
    if coupling == "kinematic" and not _identity(robot.coupling):
        notes.append(_coupling_note(robot))
        notes.append(coupling_line(robot))
    else:
        notes.append("Joints j1..jN take the controller angles (radians / metres).")
    notes.append(
        "kinecal tip link: flange (the robot's flange, for import-urdf and --robot)."
    )
    notes.append("kinecal base link: base (the robot base: the frame of kinecal fk).")
    notes.append(_limits_note(robot))
    err = check_chain(cal, chain, set_label, rng_q)
    if err > 1e-9:  # pragma: no cover - a defect, not a user error
        raise RuntimeError(f"export-urdf: the chain misses the model by {err:.2e}.")
    split = stable_splits(cal, set_label=set_label, coupling=coupling)
    if names == "robot":
        named, renamed = robot_named_chain(robot, chain)
        split = frozenset(renamed.get(s, s) for s in split)
        Tb = np.linalg.inv(chain.T_user_base)
        for label, tip in chain.tips.items():
            d = named.fk(rng_q, named.tips[label]) - Tb @ chain.fk(rng_q, tip)
            if np.abs(d).max() > 1e-9:  # pragma: no cover - a defect
                raise RuntimeError("export-urdf --names robot: renaming moved a frame.")
        chain = named
        notes = [
            n.replace("Joints j1..jN", "The joints").replace("j1..jN", "the joints")
            for n in notes
        ]
        notes.append(
            "Root base_link = the calibrated robot base; the measurement frame is the "
            "fixed child link 'user'."
        )
    return urdf_text(
        chain,
        name=f"{robot.name}_calibrated",
        comments=notes,
        split=split,
        rates=joint_rates(robot, chain),
    )


def _limits_note(robot: RobotDescription) -> str:
    known = [j.velocity is not None for j in robot.joints]
    return (
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


def _dh_text(
    cal: CalibratedModel,
    notes: list[str],
    set_label: str | None,
    marker: str | None,
    warnings: list[str],
) -> str:
    """The calibrated DH table as a robot YAML (checked against the model)."""
    from kinecal.compensation import dh_description
    from kinecal.geometry import transform_to_euler
    from kinecal.io import robot_yaml_text

    desc, T_user_base = dh_description(cal, set_label=set_label, marker=marker)
    e = transform_to_euler(T_user_base)
    notes = [
        ln.replace("Lengths in metres, angles in radians (URDF).", "") for ln in notes
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
    rng_q = _random_poses(cal.model.robot, 256)
    err = _check_yaml(cal, text, T_user_base, set_label, marker, rng_q)
    if err > 1e-9:
        warnings.append(
            f"the DH table reproduces the model to {err * 1e3:.2e} mm only "
            "(nearly parallel axes put the common normal far away)."
        )
    return text


def _identity(C: np.ndarray) -> bool:
    return bool(np.array_equal(C, np.eye(C.shape[0])))


def coupling_line(robot: RobotDescription) -> str:
    """The machine-readable coupling line of a URDF whose joints take kinematic angles
    (read back by :func:`kinecal.robot.robot_from_urdf`)."""
    C = robot.coupling
    terms = [
        f"J{i + 1} += {float(C[i, k])!r} * J{k + 1}"
        for i in range(C.shape[0])
        for k in map(int, np.flatnonzero(C[i]))
        if k != i
    ]
    return "kinecal coupling (theta = C q_ctrl): " + "; ".join(terms)


def _coupling_note(robot: RobotDescription) -> str:
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


def _compliance_lines(cal: CalibratedModel) -> list[str]:
    lay = cal.model.layout
    out = []
    for i, ps in enumerate(lay.specs):
        if ps.group in ("ntm", "load", "link") and cal.params[i] != 0.0:
            v = cal.params[i] * ps.unit.to_file
            out.append(f"  {ps.name} = {v:.6g} {ps.unit.file_unit}")
    if cal.reference_payload_kg is not None:
        out.append(f"  (reference payload {cal.reference_payload_kg:g} kg)")
    return out if np.size(out) else ["  (none)"]


def _random_poses(robot: RobotDescription, n: int) -> np.ndarray:
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    return np.random.default_rng(0).uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))


def _loss_poses(
    cal: CalibratedModel, data: str | None, targets: str | None
) -> tuple[Any, str, list[str]]:
    """Model inputs on which to state the accuracy lost, a description of them, and
    lines comparing both models with the measurements (when there are any)."""
    from kinecal.compensation import kinematic_params
    from kinecal.errors import CalibError
    from kinecal.io import read_measurements
    from kinecal.models import ModelInputs

    meas = None
    source: object = data
    if data is not None:
        meas = cal.align(read_measurements(data, cal.model.robot, targets))
    else:  # the calibration data, when the model names a file that reads
        source = cal.info.get("source")
        # a path the model file names (resolved from its folder by load_model)
        if (
            isinstance(source, str)
            and Path(source).is_absolute()
            and Path(source).is_file()
        ):
            try:
                meas = cal.align(read_measurements(source, cal.model.robot, targets))
            except CalibError:
                meas = None
    if meas is None:
        q = _random_poses(cal.model.robot, 1000)
        return ModelInputs.make(q), "1000 random poses inside the joint limits", []
    name = Path(str(source)).name
    inputs = meas.model_inputs(cal.reference_payload_kg)
    full = cal.metrics(meas)
    geo = replace(cal, params=kinematic_params(cal)).metrics(meas)
    lines = [
        f"Against the measurements of {name}: full model "
        f"{full.rms_mm:.4f} mm RMS, kinematic part {geo.rms_mm:.4f} mm RMS."
    ]
    return inputs, f"the {meas.n} poses of {name}", lines


def _check_yaml(
    cal: CalibratedModel,
    text: str,
    T_user_base: np.ndarray,
    set_label: str | None,
    marker: str | None,
    q: np.ndarray,
) -> float:
    """Largest distance [m] between the written DH table (read back) and the model."""
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


def labels_text(own: tuple[str, ...], what: str = "set") -> str:
    """What ``--set`` (``--marker``) of a model may name, for a message: its labels,
    or, for a model of the default one only (data without the column), that it has
    nothing to choose (never ``''``)."""
    if own == ("",):
        return f"none: the model has only the default {what} (leave --{what} out)"
    return "one of " + ", ".join(repr(x) if x else f"the default {what}" for x in own)
