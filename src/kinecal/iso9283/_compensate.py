"""The ISO 9283 test program compensated with a calibrated model (the *after* test).

The cube's points are defined in the robot base frame. A calibrated model predicts the
tool in its user (instrument) frame, so each point is mapped there through the model's
user frame, ``p_user = T_user_base p_base``, and the controller angles that the model maps
onto it are found by its inverse kinematics (the compensation IK, started from the
nominal program's angles, which pick the branch). Measuring this program and evaluating
it with :func:`~kinecal.iso9283.evaluate_iso9283` gives the accuracy after compensation.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinecal.errors import DataError
from kinecal.iso9283._cube import POINT_LABELS
from kinecal.iso9283._plan import IsoPlan
from kinecal.measurement import CalibratedModel
from kinecal.models import solve_ik
from kinecal.typing import Float

__all__ = ["compensated_plan", "user_from_base"]


def user_from_base(cal: CalibratedModel, set_index: int = 0) -> tuple[Float, Float]:
    """``(R_user_base (3, 3), t_user_base (3,))``: the robot base frame (the robot
    description's) in the user frame of set ``set_index`` of ``cal``."""
    R_um, t_um = cal.model.base_frames(cal.params)  # user <- model base, per set
    T_rm = cal.model.T_robotbase_modelbase  # robot base <- model base
    R_ur = R_um[set_index] @ T_rm[:3, :3].T
    return R_ur, t_um[set_index] - R_ur @ T_rm[:3, 3]


def compensated_plan(
    plan: IsoPlan, calibrated: CalibratedModel, *, set_index: int = 0
) -> IsoPlan:
    """``plan`` with the controller angles that ``calibrated`` puts on the cube points.

    Parameters
    ----------
    plan : the nominal test program (:func:`~kinecal.iso9283.plan_iso9283`).
    calibrated : a calibrated model of the same robot.
    set_index : which of the model's user frames the points are mapped through.

    Raises
    ------
    DataError
        Another robot, or a point the compensated robot cannot reach within its limits.
    """
    model = calibrated.model
    if model.n_joints != plan.q_points.shape[1]:
        raise DataError(
            f"the plan has {plan.q_points.shape[1]} joints; the model's robot "
            f"{model.robot.name} has {model.n_joints}."
        )
    if not 0 <= set_index < len(model.spec.sets):
        raise ValueError(f"set_index must lie in 0..{len(model.spec.sets) - 1}.")
    R_ub, t_ub = user_from_base(calibrated, set_index)
    p_user = plan.cube.points @ R_ub.T + t_ub
    rot = bool(model.spec.cam_rotation)
    R_user = np.broadcast_to(R_ub @ plan.R_base_tool, (5, 3, 3)) if rot else None
    ik = solve_ik(
        model,
        calibrated.params,
        p_user,
        plan.q_points,
        R_target=R_user,
        set_index=np.full(5, set_index, np.intp),
        method="lm",
    )
    bad = np.flatnonzero(~ik.converged)
    if bad.size:
        raise DataError(
            f"ISO point(s) {', '.join(POINT_LABELS[i] for i in bad)}: the calibrated "
            "model does not reach them within the joint limits (compensation did not "
            "converge); expected a smaller --cube-mm or another --cube-centre."
        )
    q = ik.q_ctrl
    return replace(plan, q_points=q, q_ctrl=q[plan.point_index])
