"""The measurement set-up a plan is made for: model, nominal frames, instrument, targets.

Three instruments, as the measurement kinds of the calibration (DESIGN §7):

* ``tracker``: a point on the tool (reflector) in the user frame (position rows);
* ``pose``: the point plus the tool orientation (6-D tracker);
* ``sensor``: a target (sphere centre, known in the user frame) seen in the cam frame;
  the prediction is the target point mapped into the user frame (Eq. 6).

The user frame is where the instrument or the targets are: ``T_user_base`` (the robot
base in it) defaults to the identity. The tool (reflector or sensor frame) is the robot
file's ``tool`` unless given.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal.errors import DataError
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = ["INSTRUMENTS", "Instrument", "candidate_inputs", "planning_model"]

INSTRUMENTS = ("tracker", "pose", "sensor")
_KIND = {"tracker": "point", "pose": "pose", "sensor": "sensor"}


@dataclass(frozen=True)
class Instrument:
    """What measures each pose, and how well.

    Attributes
    ----------
    name : 'tracker', 'pose' or 'sensor'
    noise : per-axis standard deviation of a measured position [m].
    noise_rot : standard deviation of a measured orientation [rad] ('pose' only).
    targets : (K, 3) target centres in the user frame [m] ('sensor' only).
    """

    name: str = "tracker"
    noise: float = 1e-5
    noise_rot: float = 3.5e-5
    targets: Float | None = None

    def __post_init__(self) -> None:
        if self.name not in INSTRUMENTS:
            raise ValueError(
                f"instrument must be one of {', '.join(INSTRUMENTS)}; got {self.name!r}."
            )
        for what in ("noise", "noise_rot"):
            v = getattr(self, what)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"{what} must be positive; got {v!r}.")
        if self.name == "sensor":
            t = None if self.targets is None else np.asarray(self.targets, float)
            if t is None or t.ndim != 2 or t.shape[1] != 3 or t.shape[0] < 1:
                raise ValueError(
                    "a sensor plan needs targets of shape (K, 3) in the user frame [m]."
                )

    @property
    def kind(self) -> str:
        """The measurement kind of the calibration: 'point', 'pose' or 'sensor'."""
        return _KIND[self.name]


def planning_model(
    robot: RobotDescription,
    model: str,
    instrument: Instrument,
    T_user_base: Float | None = None,
    T_flange_tool: Float | None = None,
) -> tuple[CalibrationModel, Float]:
    """The calibration model of a preset for this instrument, at nominal kinematics.

    Parameters
    ----------
    robot : RobotDescription
    model : 'kinematic', 'ntm', 'rfcm' or 'full'
    instrument : Instrument (decides whether the tool rotation is observable).
    T_user_base : (4, 4), optional
        The robot base (controller World frame) in the user frame [m]; default identity.
    T_flange_tool : (4, 4), optional
        The tool (reflector, sensor frame) in the physical flange frame [m]; default the
        robot's. A reflector off the last joint's axis lets the data see that axis.

    Returns
    -------
    (CalibrationModel, (P,) nominal parameters with the user frame set)
    """
    if T_flange_tool is not None:
        T_ft = np.asarray(T_flange_tool, np.float64)
        if T_ft.shape != (4, 4):
            raise ValueError(f"T_flange_tool must have shape (4, 4); got {T_ft.shape}.")
        robot = replace(robot, T_flange_tool=T_ft)
    spec = ModelSpec.preset(
        model,
        cam_rotation=instrument.kind != "point",
        ntm_joints=robot.ntm_joints,
        has_self_weight=robot.self_weight is not None,
        link_bodies=robot.link_bodies,
    )
    cm = CalibrationModel(robot, spec)
    x = cm.nominal.copy()
    if T_user_base is not None:
        T = np.asarray(T_user_base, np.float64)
        if T.shape != (4, 4):
            raise ValueError(f"T_user_base must have shape (4, 4); got {T.shape}.")
        T_user_modelbase = T @ cm.T_robotbase_modelbase
        cm = cm.with_references(R_ref_base=T_user_modelbase[None, :3, :3])
        x[cm.base_index[0]] = [*T_user_modelbase[:3, 3], 0.0, 0.0, 0.0]
    return cm, x


def candidate_inputs(
    model: CalibrationModel,
    params: Float,
    q_ctrl: Float,
    instrument: Instrument,
    target_index: np.ndarray | None = None,
) -> tuple[ModelInputs, np.ndarray | None]:
    """Model inputs of candidate poses and, for a sensor, the target each one sees.

    Parameters
    ----------
    model, params : the planning model at its design point.
    q_ctrl : (N, n) candidate controller angles [rad].
    instrument : Instrument
    target_index : (N,) int, optional
        Target of each sensor pose; default the target closest to the optical axis
        (the cam z axis) in front of the sensor.

    Returns
    -------
    (ModelInputs with ``p_cam`` the target in the nominal cam frame for a sensor, the
    (N,) target index or None)
    """
    q = np.asarray(q_ctrl, np.float64)
    if q.ndim != 2 or q.shape[1] != model.n_joints:
        raise DataError(
            f"candidate poses must have shape (N, {model.n_joints}); got {q.shape}."
        )
    if instrument.name != "sensor":
        return ModelInputs.make(q), None
    assert instrument.targets is not None
    tg = np.asarray(instrument.targets, np.float64)
    out = model.evaluate(params, ModelInputs.make(q), orientation=True)
    assert out.R_user_cam is not None
    d = tg[None, :, :] - out.p_user[:, None, :]  # (N, K, 3) cam origin -> targets
    d_cam = np.einsum("nji,nkj->nki", out.R_user_cam, d)
    if target_index is None:
        dist = np.linalg.norm(d_cam, axis=2)
        cos = d_cam[:, :, 2] / np.maximum(dist, 1e-12)
        ti = np.argmax(cos, axis=1)
    else:
        ti = np.asarray(target_index, np.intp)
        if ti.shape != (q.shape[0],) or ti.min() < 0 or ti.max() >= tg.shape[0]:
            raise DataError(
                f"target_index must hold one of 0..{tg.shape[0] - 1} per pose."
            )
    p_cam = d_cam[np.arange(q.shape[0]), ti]
    return ModelInputs.make(q, p_cam=p_cam), ti
