"""Corrected joint targets from a calibrated model (DESIGN §10).

Given tool points (optionally with orientations) wanted in the user frame and the program's
nominal joints as seeds (they pick the IK branch), find controller angles that the
calibrated model - kinematics, transmission errors and compliance - maps onto the targets.
Position-only targets keep the tool orientation the robot has at the seed. The output is
what a controller loads: controller angles, coupling undone (FANUC J3 from the horizontal).

.. math:: q^* = \\arg\\min_q \\| p_{model}(q) - p_{target} \\|, \\quad q \\in [q_{lo}, q_{hi}]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import DataError
from kinecal.identification import CalibratedModel
from kinecal.models import ModelInputs, solve_ik
from kinecal.typing import Float

__all__ = ["STATUS", "CompensationResult", "compensate"]

STATUS = ("ok", "unreachable", "joint_limit")


@dataclass(frozen=True)
class CompensationResult:
    """Corrected controller angles and how well they reach each target.

    Attributes
    ----------
    q_ctrl : (N, n) corrected controller joint values [rad; m for prismatic joints].
    error : (N,) position error the calibrated model predicts at ``q_ctrl`` [m].
    rotation_error : (N,) orientation error the model predicts [rad].
    status : (N,) str: 'ok', 'unreachable' (error above tolerance) or 'joint_limit'
        (the solution would need a joint beyond its limit).
    iterations : int
    """

    q_ctrl: Float
    error: Float
    rotation_error: Float
    status: np.ndarray
    iterations: int

    @property
    def ok(self) -> np.ndarray:
        return self.status == "ok"


def compensate(
    calibrated: CalibratedModel,
    p_target: Float,
    q_seed: Float,
    *,
    R_target: Float | None = None,
    set_index: np.ndarray | None = None,
    marker_index: np.ndarray | None = None,
    tol: float = 1e-6,
    tol_rotation: float = 1e-6,
    max_iter: int = 50,
) -> CompensationResult:
    """Controller angles that put the calibrated tool point on each target.

    Parameters
    ----------
    calibrated : CalibratedModel
    p_target : (N, 3) wanted tool points in the user frame [m].
    q_seed : (N, n) the program's nominal controller angles [rad].
    R_target : (N, 3, 3), optional wanted tool orientations; default: keep the seed's.
    set_index, marker_index : which user frame / tool marker each row uses (default 0).
    tol, tol_rotation : a row is 'ok' when the model error is below these [m, rad].
    """
    model = calibrated.model
    n = model.n_joints
    p = np.asarray(p_target, dtype=np.float64)
    q0 = np.asarray(q_seed, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise DataError(f"p_target must have shape (N, 3); got {p.shape}.")
    if q0.shape != (p.shape[0], n):
        raise DataError(f"q_seed must have shape ({p.shape[0]}, {n}); got {q0.shape}.")
    lim = model.robot.limits
    outside = np.any((q0 < lim[:, 0]) | (q0 > lim[:, 1]), axis=1)
    q_start = np.clip(q0, lim[:, 0], lim[:, 1])
    R_t = R_target
    if R_t is None:
        inp = ModelInputs.make(q_start, set_index=set_index, marker_index=marker_index)
        R_t = model.evaluate(calibrated.params, inp, orientation=True).R_user_cam
    res = solve_ik(
        model,
        calibrated.params,
        p,
        q_start,
        R_target=R_t,
        set_index=set_index,
        marker_index=marker_index,
        tol_position=min(tol, 1e-10) if tol > 0 else 1e-10,
        tol_rotation=min(tol_rotation, 1e-9),
        max_iter=max_iter,
    )
    status = np.full(p.shape[0], "ok", dtype=object)
    bad_err = (res.position_error > tol) | (res.rotation_error > tol_rotation)
    status[bad_err] = "unreachable"
    # A solution pinned to a limit that still misses is a limit problem, not reach.
    at_limit = np.any(
        np.isclose(res.q_ctrl, lim[:, 0], atol=1e-9)
        | np.isclose(res.q_ctrl, lim[:, 1], atol=1e-9),
        axis=1,
    )
    status[bad_err & (at_limit | outside)] = "joint_limit"
    status[~res.within_limits] = "joint_limit"
    return CompensationResult(
        res.q_ctrl,
        res.position_error,
        res.rotation_error,
        status.astype(str),
        res.iterations,
    )
