"""Corrected joint targets from a calibrated model (DESIGN §10).

Given tool points (optionally with orientations) wanted in the user frame and the program's
nominal joints as seeds (they pick the IK branch), find controller angles that the
calibrated model - kinematics, transmission errors and compliance - maps onto the targets.

A point target (position only) is met exactly and keeps the tool orientation the model
gives at the seed as closely as the position allows (exactly, away from singular poses).
A pose target (with orientation) must meet both. The output is what a controller loads:
controller angles, coupling undone (FANUC J3 from the horizontal), with per target the
predicted residual, the condition number of the task there and the joint change.

.. math:: q^* = \\arg\\min_q \\| p_{model}(q) - p_{target} \\|, \\quad q \\in [q_{lo}, q_{hi}]
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal.errors import DataError
from kinecal.measurement import CalibratedModel
from kinecal.models import ModelInputs, solve_ik_lm
from kinecal.typing import ArrayLike, Float

__all__ = ["STATUS", "CompensationResult", "compensate", "program_targets"]

STATUS = ("ok", "unreachable", "joint_limit")
# Targets solved at once: more are solved by chunks of this many (the IK's state is a few
# hundred numbers a target; 1e6 targets took 2.7 GB at once). Every target is solved
# on its own, so the chunks give the same numbers.
CHUNK = 50_000
# The most orientation a pose target gives up for the least joint motion [rad]: next to a
# singular pose a sub-millimetre correction turns the tool by a few hundredths of a degree.
_RELAX_MAX = float(np.radians(0.1))
# The condition number of the pose task (1 rad as 0.5 m) above which a pose is next to a
# singular one; the IK leaves out directions below 2 % of the largest (50).
_SINGULAR_COND = 20.0
_ROW_FIELDS = (
    "q_ctrl",
    "q_program",
    "error",
    "rotation_error",
    "status",
    "limit_joint",
    "cond",
    "relaxed",
)


@dataclass(frozen=True)
class CompensationResult:
    """Corrected controller angles and how well they reach each target.

    Attributes
    ----------
    q_ctrl : (N, n) corrected controller joint values [rad; m for prismatic joints].
    q_program : (N, n) the program's joints (the seeds) [rad; m].
    error : (N,) position error the calibrated model predicts at ``q_ctrl`` [m].
    rotation_error : (N,) orientation error the model predicts [rad] (for point targets:
        how far the tool turned from the seed's orientation to meet the point).
    status : (N,) str: 'ok', 'unreachable' (out of reach of the model, joint limits or
        not) or 'joint_limit' (reachable only with a joint beyond its limit: see
        ``limit_joint``).
    limit_joint : (N,) int, 0-based joint that would have to go furthest beyond its limit
        for a 'joint_limit' target, else -1.
    cond : (N,) condition number of the task Jacobian at the solution (position rows for
        point targets).
    iterations : int, the most iterations any target needed.
    relaxed : (N,) bool, pose targets met in position only, with the least joint motion
        (a wrist or shoulder singularity: meeting the orientation exactly would swing
        joints far for a tiny turn; ``rotation_error`` says how far the tool is turned).
    """

    q_ctrl: Float
    q_program: Float
    error: Float
    rotation_error: Float
    status: np.ndarray
    limit_joint: np.ndarray
    cond: Float
    iterations: int
    relaxed: np.ndarray | None = None

    @property
    def ok(self) -> np.ndarray:
        return self.status == "ok"

    @property
    def joint_change(self) -> Float:
        """``q_ctrl - q_program`` (N, n) [rad; m]."""
        return self.q_ctrl - self.q_program


@one_blas_thread()
def compensate(
    calibrated: CalibratedModel,
    p_target: ArrayLike,
    q_seed: ArrayLike,
    *,
    R_target: ArrayLike | None = None,
    set_index: np.ndarray | None = None,
    marker_index: np.ndarray | None = None,
    load_scale: ArrayLike | None = None,
    tol: float = 1e-6,
    tol_rotation: float = 1e-6,
    max_iter: int = 50,
    least_motion_deg: float | None = 1.0,
    p_cam: ArrayLike | None = None,
) -> CompensationResult:
    """Controller angles that put the calibrated tool point on each target.

    Parameters
    ----------
    calibrated : CalibratedModel
    p_target : (N, 3) wanted tool points in the user frame [m].
    q_seed : (N, n) the program's nominal controller angles [rad; m].
    R_target : (N, 3, 3), optional wanted tool orientations in the user frame (pose
        targets); default: point targets, keeping the seed's orientation where possible.
    set_index, marker_index : (N,) which user frame / tool marker each row uses (default 0).
    load_scale : (N,) payload relative to the model's reference payload (default 1).
    tol, tol_rotation : a row is 'ok' when the model error is below these [m, rad]
        (orientation only for pose targets).
    max_iter : iterations of the damped least-squares phase of the IK.
    least_motion_deg : pose targets that move a joint by more than this [deg], or that
        are not met, are solved again as point targets keeping the wanted orientation
        where it is well conditioned (a controller's handling of singular poses): taken
        when that meets the position with less joint motion (``relaxed``). None: off.
    p_cam : (N, 3), optional the point of the cam frame put on ``p_target`` (a tool
        point; default the cam origin) [m].

    Raises
    ------
    DataError
        Wrong shapes or non-finite values.
    """
    model = calibrated.model
    p, q0, ls = _checked_targets(model.n_joints, p_target, q_seed, load_scale)
    if p.shape[0] > CHUNK:  # large programs by chunks of targets: memory stays small
        kw = dict(
            R_target=R_target, set_index=set_index, marker_index=marker_index,
            load_scale=ls, p_cam=p_cam,
        )  # fmt: skip
        fixed = dict(
            tol=tol, tol_rotation=tol_rotation, max_iter=max_iter,
            least_motion_deg=least_motion_deg,
        )  # fmt: skip
        return _by_chunks(calibrated, p, q0, kw, fixed)
    res = solve_ik_lm(
        model,
        calibrated.params,
        p,
        q0,
        R_target=R_target,
        set_index=set_index,
        marker_index=marker_index,
        load_scale=ls,
        tol_position=min(tol, 1e-11),
        tol_rotation=min(tol_rotation, 1e-10),
        max_iter=max_iter,
        p_cam=p_cam,
    )
    pose = R_target is not None
    relaxed = np.zeros(p.shape[0], bool)
    if pose and least_motion_deg is not None:
        res, relaxed = _least_motion(
            model, calibrated.params, res, p, q0, R_target,
            set_index, marker_index, ls, tol, tol_rotation, max_iter,
            np.radians(least_motion_deg), p_cam,
        )  # fmt: skip
    ok = (res.position_error <= tol) & res.within_limits
    if pose:
        ok &= (res.rotation_error <= tol_rotation) | relaxed
    status = np.where(ok, "ok", "unreachable").astype(object)
    limit_joint = np.full(ok.shape, -1)
    bad = np.flatnonzero(~ok)
    if bad.size:  # which of the missed targets a joint limit stops
        blamed, joint = _blame_limits(
            model, calibrated.params, res, p, q0, bad, R_target, set_index,
            marker_index, ls, p_cam, tol, tol_rotation, max_iter,
        )  # fmt: skip
        limit_joint[bad[blamed]] = joint
        status[bad[blamed]] = "joint_limit"
    assert res.cond is not None
    return CompensationResult(
        res.q_ctrl,
        q0.copy(),
        res.position_error,
        res.rotation_error,
        status.astype(str),
        limit_joint,
        res.cond,
        res.iterations,
        relaxed,
    )


def _checked_targets(
    n: int, p_target: ArrayLike, q_seed: ArrayLike, load_scale: ArrayLike | None
) -> tuple[Float, Float, Float | None]:
    """The targets [m], seeds [rad; m] and payload scales as float arrays, checked.

    Raises
    ------
    DataError
        Wrong shapes or non-finite values.
    """
    p = np.asarray(p_target, dtype=np.float64)
    q0 = np.asarray(q_seed, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise DataError(f"p_target must have shape (N, 3); got {p.shape}.")
    if q0.shape != (p.shape[0], n):
        raise DataError(f"q_seed must have shape ({p.shape[0]}, {n}); got {q0.shape}.")
    if not (np.isfinite(p).all() and np.isfinite(q0).all()):
        raise DataError("p_target and q_seed must be finite.")
    ls = None if load_scale is None else np.asarray(load_scale, np.float64).reshape(-1)
    return p, q0, ls


def _by_chunks(
    calibrated: CalibratedModel,
    p: Float,
    q0: Float,
    per_row: dict[str, Any],
    fixed: dict[str, Any],
) -> CompensationResult:
    """:func:`compensate` by chunks of :data:`CHUNK` targets, joined."""
    parts = []
    for lo in range(0, p.shape[0], CHUNK):
        rows = slice(lo, lo + CHUNK)
        cut: dict[str, Any] = {
            k: None if v is None else np.asarray(v)[rows] for k, v in per_row.items()
        }
        parts.append(compensate(calibrated, p[rows], q0[rows], **cut, **fixed))
    joined = {f: np.concatenate([getattr(r, f) for r in parts]) for f in _ROW_FIELDS}
    return CompensationResult(
        **{k: v for k, v in joined.items() if k != "relaxed"},
        iterations=max(r.iterations for r in parts),
        relaxed=joined["relaxed"],
    )


def _blame_limits(
    model, params, res, p, q0, bad, R_target, set_index, marker_index, ls, p_cam, tol,
    tol_rotation, max_iter,
):  # fmt: skip
    """Beyond the limits or out of reach? The failed rows ``bad`` solved again without
    limits, from the seeds ``q0`` (a program's joints beyond a limit: the limited
    solution can sit on a branch that no longer reaches) and from the limited solution:
    where either meets the target (or comes a thousand times nearer), the joint
    furthest outside its limit is to blame.
    Returns (blamed (B,) bool over ``bad``, their 0-based joints)."""

    def cut(v):
        return None if v is None else np.asarray(v)[bad]

    def solve(start):
        return solve_ik_lm(
            model, params, p[bad], start, R_target=cut(R_target),
            point_only=R_target is None, set_index=cut(set_index),
            marker_index=cut(marker_index), load_scale=cut(ls),
            limits=np.tile([-np.inf, np.inf], (model.n_joints, 1)), p_cam=cut(p_cam),
            tol_position=min(tol, 1e-11), tol_rotation=min(tol_rotation, 1e-10),
            max_iter=max_iter,
        )  # fmt: skip

    def met(r):  # or a thousand times nearer than within the limits: a singular
        # pose (a wrist at 0 deg, a home position) converges slowly
        e_p, e_r = res.position_error[bad], res.rotation_error[bad]
        ok = r.position_error <= np.maximum(tol, 1e-3 * e_p)
        if R_target is not None:
            ok &= r.rotation_error <= np.maximum(tol_rotation, 1e-3 * e_r)
        return ok

    free, again = solve(q0[bad]), solve(res.q_ctrl[bad])
    use = ~met(free) & met(again)
    q_free = np.where(use[:, None], again.q_ctrl, free.q_ctrl)
    lim = model.robot.limits
    outside = np.maximum(lim[:, 0] - q_free, q_free - lim[:, 1])
    reached = met(free) | met(again)
    blame = reached & (outside.max(axis=1) > 0)
    return blame, np.argmax(outside[blame], axis=1)


def _least_motion(
    model, params, res, p, q0, R_target, set_index, marker_index, ls, tol,
    tol_rotation, max_iter, dq_max, p_cam=None,
):  # fmt: skip
    """Pose rows not met or moving a joint by more than ``dq_max`` [rad], solved again as
    point targets that keep the orientation where it is well conditioned; a row takes the
    new solution when it meets the position within the limits with less joint motion."""
    from dataclasses import replace

    motion = np.abs(res.q_ctrl - q0).max(axis=1)
    met = (res.position_error <= tol) & (res.rotation_error <= tol_rotation)
    met &= res.within_limits
    # Only next to a singular pose: elsewhere a target not met is out of reach or beyond
    # a limit, and giving up orientation there would hide it.
    rows = np.flatnonzero((~met | (motion > dq_max)) & (res.cond > _SINGULAR_COND))
    relaxed = np.zeros(p.shape[0], bool)
    if rows.size == 0:
        return res, relaxed

    def cut(v):
        return None if v is None else np.asarray(v)[rows]

    again = solve_ik_lm(
        model, params, p[rows], q0[rows], R_target=np.asarray(R_target)[rows],
        point_only=True, set_index=cut(set_index), marker_index=cut(marker_index),
        load_scale=cut(ls), p_cam=cut(p_cam), tol_position=min(tol, 1e-11),
        tol_rotation=min(tol_rotation, 1e-10), max_iter=max_iter,
    )  # fmt: skip
    new_motion = np.abs(again.q_ctrl - q0[rows]).max(axis=1)
    take = (again.position_error <= tol) & again.within_limits
    take &= (new_motion < motion[rows]) | ~met[rows]
    take &= again.rotation_error <= _RELAX_MAX  # a tiny turn given up, not a target
    sel = rows[take]
    fields = {}
    for f in ("q_ctrl", "position_error", "rotation_error", "within_limits", "cond"):
        a = getattr(res, f).copy()
        a[sel] = getattr(again, f)[take]
        fields[f] = a
    relaxed[sel] = again.rotation_error[take] > tol_rotation  # the orientation given up
    return replace(res, **fields), relaxed


def program_targets(
    calibrated: CalibratedModel,
    q_program: ArrayLike,
    *,
    set_index: np.ndarray | None = None,
    marker_index: np.ndarray | None = None,
) -> tuple[Float, Float]:
    """Where a program's joint targets are meant to put the tool: the pose the *nominal*
    robot has there (the program was taught or planned on it), hanging from the
    calibrated base and carrying the calibrated tool.

    That is the calibrated model with its joint rows nominal and no compliance or
    transmission terms. Compensating to these poses (position and orientation) makes the
    real flange take the nominal flange pose, so any tool defined on the controller
    lands where the program meant.

    Returns
    -------
    p_user : (N, 3) [m] and R_user_cam : (N, 3, 3), in the user frame.
    """
    from kinecal.compensation._export import kinematic_params

    model = calibrated.model
    x = kinematic_params(calibrated)
    joints = model.layout.group_indices("joint")
    x[joints] = model.nominal[joints]
    inp = ModelInputs.make(q_program, set_index=set_index, marker_index=marker_index)
    out = model.evaluate(x, inp, orientation=True)
    assert out.R_user_cam is not None
    return out.p_user, out.R_user_cam
