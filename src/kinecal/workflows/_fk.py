"""The workflows of ``kinecal fk`` (a pose from joint angles, nominal or calibrated) and
``kinecal import-urdf`` (a robot YAML from a URDF's serial chain)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinecal.errors import DataError
from kinecal.measurement import CalibratedModel
from kinecal.robot import RobotDescription
from kinecal.workflows._args import need_robot

__all__ = ["ImportedRobot", "PoseReport", "forward_pose", "import_urdf_robot"]


@dataclass(frozen=True)
class PoseReport:
    """What :func:`forward_pose` found (file units: mm, deg; FANUC W, P, R).

    Attributes
    ----------
    robot : the robot's name.
    flange_mm, wpr_deg : the flange in the robot base frame.
    tool_mm, tool_wpr_deg : a model's tool point (cam origin) in the user frame (None
        for a nominal robot).
    kinematic : the same without the compliance and transmission terms (a model only).
    payload_kg, set, marker : the load and the frames a model's pose is for.
    """

    robot: str
    flange_mm: list[float]
    wpr_deg: list[float]
    tool_mm: list[float] | None = None
    tool_wpr_deg: list[float] | None = None
    kinematic: PoseReport | None = None
    payload_kg: float | None = None
    set: str | None = None
    marker: str | None = None

    def lines(self, model_path: str | None = None) -> list[str]:
        """The lines ``kinecal fk`` prints: the nominal flange, or (``model_path``: a
        model's pose) the flange and tool point with all terms and without the
        compliance and transmission terms."""
        if model_path is None or self.kinematic is None:
            return [
                f"robot   {self.robot}",
                "flange  x {:.4f}  y {:.4f}  z {:.4f}  mm".format(*self.flange_mm),
                "        w {:.4f}  p {:.4f}  r {:.4f}  deg".format(*self.wpr_deg),
            ]
        out = [f"model   {model_path} ({self.robot})"]
        for title, d in (("with all terms", self), ("kinematic part", self.kinematic)):
            assert d.tool_mm is not None and d.tool_wpr_deg is not None
            out.append(f"{title}:")
            for what, xyz, wpr in (
                ("flange (base)", d.flange_mm, d.wpr_deg),
                ("tool   (user)", d.tool_mm, d.tool_wpr_deg),
            ):
                out.append(
                    f"  {what} x {xyz[0]:.4f}  y {xyz[1]:.4f}  z {xyz[2]:.4f}  mm"
                )
                out.append(
                    f"                 w {wpr[0]:.4f}  p {wpr[1]:.4f}  r {wpr[2]:.4f}  deg"
                )
        return out

    def as_dict(self) -> dict[str, Any]:
        """The JSON object ``kinecal fk --json`` prints."""
        if self.tool_mm is None:
            return {"flange_mm": self.flange_mm, "wpr_deg": self.wpr_deg}
        out = {
            "flange_mm": self.flange_mm,
            "wpr_deg": self.wpr_deg,
            "tool_mm": self.tool_mm,
            "tool_wpr_deg": self.tool_wpr_deg,
        }
        if self.kinematic is None:
            return out
        return {
            **out,
            "kinematic": self.kinematic.as_dict(),
            "payload_kg": self.payload_kg,
            "set": self.set,
            "marker": self.marker,
        }


def forward_pose(
    source: RobotDescription | CalibratedModel,
    joints: Sequence[float],
    *,
    payload_kg: float | None = None,
    set_label: str | None = None,
    marker: str | None = None,
    ignore_limits: bool = False,
) -> PoseReport:
    """The pose ``kinecal fk`` prints for controller joints ``joints`` [deg; mm if
    prismatic].

    Parameters
    ----------
    source : a robot (the nominal flange) or a calibrated model (the calibrated flange
        and tool, with and without the compliance terms).
    joints : one value per joint.
    payload_kg, set_label, marker : a model's load (default: the calibration's), user
        frame and tool marker (default: the first).
    ignore_limits : compute a pose beyond the joint limits too.

    Returns
    -------
    PoseReport
        The pose (``as_dict()``: the JSON object of ``kinecal fk --json``).

    Raises
    ------
    DataError
        A wrong number of joints, a value not finite or beyond the limits, a set or
        marker not in the model, a payload the model cannot take.
    """
    cal = source if isinstance(source, CalibratedModel) else None
    robot = source.model.robot if isinstance(source, CalibratedModel) else source
    if cal is None:
        need_robot(source, "source")
    joints = _joint_values(joints)
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
    if cal is None:
        xyz, wpr = _pose_mm_deg(robot.fk_flange(q))
        return PoseReport(robot.name, xyz, wpr)
    _warn_extrapolation(cal, q)
    return _model_fk(cal, q, payload_kg, set_label, marker)


def _warn_extrapolation(cal: CalibratedModel, q: np.ndarray) -> None:
    """Warn (as evaluate and compensate do) when a joint lies outside the range the
    model was calibrated on: its pose there is an extrapolation (it was printed as
    calibrated, unsaid)."""
    import warnings

    from kinecal.io import extrapolation

    found = extrapolation(cal, q[None], [1], "fk")
    if found is None:
        return
    robot = cal.model.robot
    rng = np.asarray(cal.info["calibrated_joint_range"], float)
    v = q * np.where(robot.prismatic, 1e3, 180.0 / np.pi)
    parts = []
    for name in found.parameters:
        j = robot.joint_names.index(name)
        unit = "mm" if robot.prismatic[j] else "deg"
        parts.append(
            f"{name} {v[j]:.1f} {unit} (calibrated {rng[j, 0]:.1f} .. {rng[j, 1]:.1f})"
        )
    source = cal.info.get("source", "the calibration data")
    warnings.warn(
        f"{'; '.join(parts)}: outside the joint ranges of {source}, which the model was "
        "calibrated on; its pose there extrapolates and can be far off.",
        stacklevel=3,
    )


def _joint_values(joints: Any) -> list[float]:
    """``joints`` as a list of numbers: one value per joint, a flat sequence."""
    from kinecal.errors import ConfigError

    a = None
    if not isinstance(joints, (str, bytes)):
        try:
            a = np.asarray(joints, dtype=float)
        except (TypeError, ValueError):
            pass
    if a is None or a.ndim != 1:
        raise ConfigError(
            "joints: expected one number per joint (a list or 1-D array); got "
            f"{type(joints).__name__}"
            + ("" if a is None or a.ndim == 0 else f" of shape {a.shape}")
            + "."
        )
    return [float(v) for v in a]


def _check_joints(
    robot: RobotDescription, joints: Sequence[float], q: np.ndarray, ignore: bool
) -> None:
    """Finite joint values, inside the joint limits unless ``ignore``."""
    for k, (v, j) in enumerate(zip(joints, robot.joints)):
        unit = "mm" if j.kind == "prismatic" else "deg"
        if not np.isfinite(v):
            raise DataError(f"J{k + 1}: expected a finite value in {unit}; got {v}.")
        lo, hi = j.limits
        if ignore or lo - 1e-12 <= q[k] <= hi + 1e-12:
            continue
        f = 1e3 if j.kind == "prismatic" else 180.0 / np.pi
        raise DataError(
            f"J{k + 1}: {v:g} {unit} is beyond the joint limits [{lo * f:g}, "
            f"{hi * f:g}] {unit} of {robot.name}; expected a value inside them "
            "(--ignore-limits computes the pose anyway)."
        )


def _pose_mm_deg(T: np.ndarray) -> tuple[list[float], list[float]]:
    from kinecal.geometry import matrix_to_wpr

    return (T[:3, 3] * 1e3).tolist(), np.degrees(matrix_to_wpr(T[:3, :3])).tolist()


def _model_fk(
    cal: CalibratedModel,
    q: np.ndarray,
    payload_kg: float | None,
    set_label: str | None,
    marker: str | None,
) -> PoseReport:
    """The calibrated flange (robot base) and tool (user frame), with and without the
    compliance terms."""
    from kinecal.compensation import flange_offset, kinematic_params, robot_base_offset
    from kinecal.models import ModelInputs
    from kinecal.workflows._export import labels_text

    spec = cal.model.spec
    idx = []
    for what, label, own in (
        ("set", set_label, spec.sets),
        ("marker", marker, spec.markers),
    ):
        if label is not None and label not in own:
            raise DataError(
                f"--{what}: {what} {label!r} is not in the model; expected "
                f"{labels_text(own, what)}."
            )
        idx.append(0 if label is None else own.index(label))
    from kinecal.workflows._compensate import load_scale

    # (the checks of compensate's --payload-kg; None: the calibration's load)
    given = load_scale(cal, payload_kg)
    scale = 1.0 if given is None else given
    inp = ModelInputs.make(
        q[None], set_index=[idx[0]], marker_index=[idx[1]], load_scale=[scale]
    )
    P0 = robot_base_offset(cal.model.robot)
    F = flange_offset(cal.model.robot)
    out = []
    for x in (cal.params, kinematic_params(cal)):
        R, o = cal.model.flange_frames(x, inp)
        T_fl = np.eye(4)
        T_fl[:3, :3], T_fl[:3, 3] = R[0], o[0]
        flange = _pose_mm_deg(P0 @ T_fl @ F)
        ev = cal.model.evaluate(x, inp, orientation=True)
        assert ev.R_user_cam is not None
        T_tool = np.eye(4)
        T_tool[:3, :3], T_tool[:3, 3] = ev.R_user_cam[0], ev.p_user[0]
        tool = _pose_mm_deg(T_tool)
        out.append((*flange, *tool))
    name = cal.model.robot.name
    return PoseReport(
        name,
        *out[0],
        kinematic=PoseReport(name, *out[1]),
        payload_kg=payload_kg if payload_kg is not None else cal.reference_payload_kg,
        set=spec.sets[idx[0]],
        marker=spec.markers[idx[1]],
    )


@dataclass(frozen=True)
class ImportedRobot:
    """What :func:`import_urdf_robot` made of a URDF.

    Attributes
    ----------
    robot : the robot (standard DH).
    text : its robot YAML (mm, deg), with a header naming the URDF.
    chain : the URDF's links the chain runs between.
    coupled : the chain has mimic joints (a coupling).
    self_weight : one line on the link masses and the joints their weight loads.
    """

    robot: RobotDescription
    text: str
    chain: str
    coupled: bool
    self_weight: str


def import_urdf_robot(
    urdf: str,
    *,
    base: str | None = None,
    tip: str | None = None,
    name: str | None = None,
) -> ImportedRobot:
    """The robot YAML ``kinecal import-urdf`` writes for the serial chain of ``urdf``
    from ``base`` (default the root link) to ``tip`` (default the end of the chain).

    The written document is read back and must give the URDF's flange poses.

    Returns
    -------
    ImportedRobot
        The robot and its YAML text.
    """
    from kinecal import _yaml as yaml
    from kinecal.robot import dump_robot, robot_from_dict, robot_from_urdf

    robot = robot_from_urdf(urdf, base=base, tip=tip, name=name)
    doc = dump_robot(robot)
    # Check the written document: it must load and give the same flange poses.
    again = robot_from_dict(yaml.load(yaml.dump(doc)), source=urdf)
    q = np.random.default_rng(0).uniform(-1.0, 1.0, (16, robot.n_joints))
    T = robot.fk_flange(q)
    err = float(np.abs(again.fk_flange(q) - T).max())
    scale = max(1.0, float(np.abs(T[..., :3, 3]).max()))  # [m]: metres or radians
    if err > 1e-9 * scale:  # pragma: no cover - a defect, not a user error
        raise RuntimeError(
            f"import-urdf: the YAML does not reproduce the URDF ({err})."
        )
    header = f"# Imported from {urdf} by kinecal import-urdf ({robot.source}).\n"
    return ImportedRobot(
        robot,
        header + yaml.dump(doc, sort_keys=False),
        robot.source.rsplit("(URDF ", 1)[-1].rstrip(")"),
        not np.array_equal(robot.coupling, np.eye(robot.n_joints)),
        _self_weight_summary(robot),
    )


def _self_weight_summary(robot: RobotDescription) -> str:
    """One line on the imported link masses and the joints their weight loads."""
    if not robot.link_bodies:
        return (
            "link masses: none in the URDF (no <inertial>); the models have no link "
            "self-weight terms (add link_masses or self_weight to the YAML)"
        )
    from kinecal.simulation import gravity_torques, random_joint_poses

    q = random_joint_poses(robot, 200, np.random.default_rng(0))
    tau = np.abs(gravity_torques(robot, q)).max(axis=0)
    loaded = [robot.joint_names[j] for j in range(robot.n_joints) if tau[j] > 1e-9]
    total = sum(b.mass for b in robot.link_masses)
    return (
        f"link masses: {len(robot.link_bodies)} bodies, {total:.3g} kg; gravity "
        f"loads joints {', '.join(loaded) or 'none'}"
    )
