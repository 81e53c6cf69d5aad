"""Corrected Cartesian targets: what the controller's nominal model must be commanded so
that the calibrated robot reaches a taught pose (issue 34).

Frames: the controller works in the robot description's base frame ``rb`` and plans with
the *nominal* kinematics (:meth:`RobotDescription.fk_flange`). The calibrated robot in that
frame is the calibrated model seen from its base: ``T_rb_flange(q) = T_rb_mb ·
inv(T_user_mb) · T_user_cam(q) · inv(T_mb_cam-part) · T_last_flange`` (the model absorbs the
nominal base and flange offsets into its user and cam frames, :mod:`._export`). A target
``T_rb_flange`` wanted is corrected by

1. the calibrated IK near the taught configuration: ``q* = IK_cal(T)``;
2. the nominal FK of those joints: ``T' = FK_nom(q*)``.

The controller, commanded ``T'`` with the same configuration flags, solves ``q*`` again
and the calibrated robot lands on ``T``. The taught configuration is found on the nominal
model from many starts, keeping the solution whose configuration flags are the program's
(:func:`branch_solutions`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from kinecal.compensation._compensate import CompensationResult, compensate
from kinecal.compensation._export import flange_offset, kinematic_params
from kinecal.geometry import make_transform, transform_inv
from kinecal.measurement import CalibratedModel
from kinecal.models import ModelInputs, solve_ik_lm
from kinecal.typing import Float, Pose

__all__ = [
    "PoseCompensation",
    "arm_features",
    "branch_solutions",
    "calibrated_flange",
    "compensate_poses",
    "nearest_solutions",
    "nominal_flange",
    "stretch_sign",
]

# Starting points of the nominal multi-start IK per target (deterministic).
N_STARTS = 64
_TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class PoseCompensation:
    """Corrected flange poses and how the calibrated robot reaches the wanted ones.

    Attributes
    ----------
    T_corrected : (N, 4, 4) the nominal flange pose of the corrected joints, in the robot
        base frame [m]: what the controller must be commanded (before its tool frame).
    result : the calibrated IK (joints, errors, status) of each wanted pose.
    """

    T_corrected: Pose
    result: CompensationResult


def _frames(cal: CalibratedModel) -> tuple[Pose, Pose, Pose]:
    """``T_rb_user`` (robot base -> user frame of set 0), ``T_last_cam`` (marker 0) and
    ``T_last_flange`` (the physical flange in the model's last link frame)."""
    m = cal.model
    Rb, tb = m.base_frames(cal.params)
    Rc, tc = m.cam_frames(cal.params)
    T_user_mb = make_transform(Rb[0], tb[0])
    T_rb_user = m.T_robotbase_modelbase @ transform_inv(T_user_mb)
    return T_rb_user, make_transform(Rc[0], tc[0]), flange_offset(m.robot)


def nominal_flange(cal: CalibratedModel, q_ctrl: Float) -> Pose:
    """The controller's nominal flange pose ``T_rb_flange`` (N, 4, 4) at ``q_ctrl``."""
    return cal.model.robot.fk_flange(q_ctrl)


def calibrated_flange(
    cal: CalibratedModel, q_ctrl: Float, load_scale: Float | None = None
) -> Pose:
    """The calibrated robot's flange pose in the robot base frame (N, 4, 4) at
    ``q_ctrl``, with every compliance and transmission term."""
    q = np.atleast_2d(np.asarray(q_ctrl, np.float64))
    out = cal.model.evaluate(
        cal.params, ModelInputs.make(q, load_scale=load_scale), orientation=True
    )
    assert out.R_user_cam is not None
    T_rb_user, T_last_cam, T_last_flange = _frames(cal)
    T_user_cam = make_transform(out.R_user_cam, out.p_user)
    return T_rb_user @ T_user_cam @ transform_inv(T_last_cam) @ T_last_flange


def _cam_targets(cal: CalibratedModel, T_rb_flange: Pose) -> tuple[Float, Float]:
    """The model's cam poses (p (N, 3), R (N, 3, 3)) in the user frame for flange poses."""
    T_rb_user, T_last_cam, T_last_flange = _frames(cal)
    T = transform_inv(T_rb_user) @ T_rb_flange @ transform_inv(T_last_flange)
    T = T @ T_last_cam
    return T[:, :3, 3].copy(), T[:, :3, :3].copy()


def _starts(cal: CalibratedModel, k: int) -> Float:
    """``k`` deterministic starting joint vectors spread over the limits (clipped to one
    turn for revolute joints)."""
    robot = cal.model.robot
    lim = robot.limits.copy()
    lim[~robot.prismatic] = np.clip(lim[~robot.prismatic], -np.pi, np.pi)
    u = np.random.default_rng(34).uniform(0.05, 0.95, (k, robot.n_joints))
    return lim[:, 0] + u * (lim[:, 1] - lim[:, 0])


def _turn_variants(cal: CalibratedModel, q: Float) -> Float:
    """Every joint vector equal to ``q`` (M, n) but for whole turns of revolute joints,
    within the limits: (M', n)."""
    robot = cal.model.robot
    lim = robot.limits
    out = q
    for j in np.flatnonzero(~robot.prismatic):
        if lim[j, 1] - lim[j, 0] <= _TWO_PI:
            continue
        shifted = [
            out + s * _TWO_PI * np.eye(robot.n_joints)[j] for s in (-2, -1, 1, 2)
        ]
        out = np.concatenate([out, *shifted])
    inside = np.all((out >= lim[:, 0] - 1e-6) & (out <= lim[:, 1] + 1e-6), axis=1)
    return out[inside]


def branch_solutions(
    cal: CalibratedModel,
    T_rb_flange: Pose,
    accept: Callable[[int, Float], np.ndarray],
    *,
    tol: float = 1e-9,
) -> tuple[Float, np.ndarray]:
    """The nominal IK solution of each flange pose whose configuration the program names.

    Parameters
    ----------
    T_rb_flange : (N, 4, 4) wanted flange poses in the robot base frame [m].
    accept : ``accept(i, q) -> (M,) bool``: which joint vectors ``q`` (M, n) have target
        i's configuration flags (and turns).

    Returns
    -------
    q : (N, n) the accepted solution with the least joint norm (NaN where none).
    found : (N,) bool.
    """
    model = cal.model
    N, n = T_rb_flange.shape[0], model.n_joints
    starts = _starts(cal, N_STARTS)
    p, R = _cam_targets(cal, T_rb_flange)
    lim = model.robot.limits + np.array([-1e-6, 1e-6])  # a target taught at a limit
    res = solve_ik_lm(
        model,
        _nominal_params(cal),
        np.repeat(p, N_STARTS, axis=0),
        np.tile(starts, (N, 1)),
        R_target=np.repeat(R, N_STARTS, axis=0),
        tol_position=1e-11,
        tol_rotation=1e-10,
        max_iter=80,
        limits=lim,
    )
    good = (res.position_error <= tol) & (res.rotation_error <= tol) & res.within_limits
    q_all = res.q_ctrl.reshape(N, N_STARTS, n)
    good = good.reshape(N, N_STARTS)
    q_all, good = _with_wrist_flips(cal, T_rb_flange, q_all, good, tol)
    q_out = np.full((N, n), np.nan)
    for i in range(N):  # the selection per target: a few dozen candidates each
        cand = _turn_variants(cal, q_all[i][good[i]])
        if cand.shape[0] == 0:
            continue
        cand = cand[accept(i, cand)]
        if cand.shape[0]:
            q_out[i] = cand[np.argmin(np.linalg.norm(cand, axis=1))]
    return q_out, np.isfinite(q_out).all(axis=1)


def _nominal_params(cal: CalibratedModel) -> Float:
    x = kinematic_params(cal)
    joints = cal.model.layout.group_indices("joint")
    x[joints] = cal.model.nominal[joints]
    return x


def nearest_solutions(
    cal: CalibratedModel, T_rb_flange: Pose, q_near: Float, *, tol: float = 1e-9
) -> tuple[Float, np.ndarray]:
    """The nominal IK solution of each flange pose reached from ``q_near`` (N, n), as a
    controller without configuration flags takes the one nearest the current joints.

    Returns q (N, n) (NaN where not found) and found (N,) bool."""
    p, R = _cam_targets(cal, T_rb_flange)
    res = solve_ik_lm(
        cal.model, _nominal_params(cal), p, q_near, R_target=R,
        tol_position=1e-11, tol_rotation=1e-10, max_iter=80,
    )  # fmt: skip
    found = (
        (res.position_error <= tol) & (res.rotation_error <= tol) & res.within_limits
    )
    return np.where(found[:, None], res.q_ctrl, np.nan), found


def _with_wrist_flips(
    cal: CalibratedModel, T: Pose, q: Float, good: np.ndarray, tol: float
) -> tuple[Float, np.ndarray]:
    """The solutions (N, K, n) and their other wrist (J4 + pi, -J5, J6 + pi), kept
    where the nominal flange pose is the same (a spherical wrist): (N, 2K, n)."""
    n = q.shape[2]
    if n < 6:
        return q, good
    flip = q.copy()
    flip[..., 3] += np.pi
    flip[..., 4] *= -1.0
    flip[..., 5] += np.pi
    flip[..., [3, 5]] = (flip[..., [3, 5]] + np.pi) % _TWO_PI - np.pi
    Tf = cal.model.robot.fk_flange(flip)
    dp = np.linalg.norm(Tf[..., :3, 3] - T[:, None, :3, 3], axis=-1)
    dR = np.abs(Tf[..., :3, :3] - T[:, None, :3, :3]).max(axis=(-2, -1))
    lim = cal.model.robot.limits
    ok = good & (dp <= 1e-3 * tol + 1e-9) & (dR <= 1e-8)
    ok &= np.all((flip >= lim[:, 0] - 1e-6) & (flip <= lim[:, 1] + 1e-6), axis=-1)
    return np.concatenate([q, flip], axis=1), np.concatenate([good, ok], axis=1)


def _joint_frames(cal: CalibratedModel, q: Float) -> Pose:
    """Nominal frames (M, n + 1, 4, 4): the base of joint 1, then after each DH row."""
    from kinecal.robot._description import dh_transforms

    robot = cal.model.robot
    ch = robot.dh_chain()
    theta = robot.theta_from_ctrl(q)
    rot = np.where(ch.prismatic, ch.theta_offset, ch.theta_offset + theta)
    dd = np.where(ch.prismatic, ch.d + theta, ch.d)
    A = dh_transforms(rot, dd, ch.a, ch.alpha)
    T = np.broadcast_to(ch.T_base_0, (q.shape[0], 4, 4)).copy()
    out = [T]
    for i in range(robot.n_joints):
        T = T @ A[:, i]
        out.append(T)
    return np.stack(out, axis=1)


def stretch_sign(cal: CalibratedModel) -> float:
    """The sign of the elbow bend just past the stretched arm, J3 increasing (J2 = 0 and
    the other joints zero): the stretched arm is where the wrist centre is furthest from
    the J2 axis."""
    n = cal.model.n_joints
    grid = np.linspace(-np.pi, np.pi, 721)
    q = np.zeros((grid.size, n))
    q[:, 2] = grid
    F = _joint_frames(cal, q)
    reach = np.linalg.norm(F[:, 4, :3, 3] - F[:, 1, :3, 3], axis=1)
    q_past = np.zeros((1, n))
    q_past[0, 2] = grid[np.argmax(reach)] + 0.3
    return float(np.sign(_bend(_joint_frames(cal, q_past)))[0])


def _bend(F: Pose) -> Float:
    o1, o2, z1, wc = F[:, 1, :3, 3], F[:, 2, :3, 3], F[:, 1, :3, 2], F[:, 4, :3, 3]
    return np.sum(np.cross(o2 - o1, wc - o2) * z1, axis=1)


def arm_features(
    cal: CalibratedModel, q_ctrl: Float, stretch: float | None = None
) -> dict[str, np.ndarray]:
    """Configuration features of 6-axis arms with a spherical wrist (M,) bool each:

    * ``front``: the wrist centre (origin after row 4) lies in front of the joint-1 axis,
      in the frame that turns with joint 1 (x > 0);
    * ``elbow``: the elbow bends to the same side as at the zero pose;
    * ``past_stretch``: the elbow bends to the side J3 reaches past the stretched arm;
    * ``wrist_neg``: J5 < 0.
    """
    q = np.atleast_2d(np.asarray(q_ctrl, np.float64))
    qq = np.vstack([np.zeros(q.shape[1]), q])
    F = _joint_frames(cal, qq)
    o0, z0, wc = F[:, 0, :3, 3], F[:, 0, :3, 2], F[:, 4, :3, 3]
    theta1 = cal.model.robot.theta_from_ctrl(qq)[:, 0]
    ex = np.broadcast_to(F[0, 0, :3, 0], o0.shape)
    # e_x of the base turned with joint 1 about its axis (Rodrigues).
    c, s = np.cos(theta1)[:, None], np.sin(theta1)[:, None]
    dot = np.sum(z0 * ex, axis=1, keepdims=True)
    u = ex * c + np.cross(z0, ex) * s + z0 * dot * (1 - c)
    front = np.sum((wc - o0) * u, axis=1) > 0
    bend = np.sign(_bend(F))
    return {
        "front": front[1:],
        "elbow": bend[1:] == bend[0],
        "past_stretch": bend[1:] == (stretch_sign(cal) if stretch is None else stretch),
        "wrist_neg": q[:, 4] < 0,
    }


def compensate_poses(
    cal: CalibratedModel,
    T_rb_flange: Pose,
    q_seed: Float,
    *,
    T_flange_tool: Pose | None = None,
    load_scale: Float | None = None,
    tol: float = 1e-6,
) -> PoseCompensation:
    """Corrected flange poses for wanted ones (N, 4, 4), each solved on the calibrated
    model from ``q_seed`` (N, n), the taught configuration (see the module docstring).

    A target next to a singular pose may be met with the least joint motion, giving up a
    tiny turn (``result.relaxed``); then the tool point ``T_flange_tool`` (N, 4, 4)
    (default: the flange) is the point held on the target, not the model's cam point.
    """
    T_want = np.asarray(T_rb_flange, np.float64)
    N = T_want.shape[0]
    p, R = _cam_targets(cal, T_want)
    tool = np.tile(np.eye(4), (N, 1, 1)) if T_flange_tool is None else T_flange_tool
    _, T_last_cam, T_last_flange = _frames(cal)
    # The tool point in the cam frame, and where it must be: the IK holds it there.
    r = (transform_inv(T_last_cam) @ T_last_flange @ tool)[:, :3, 3]
    p_tool = p + np.einsum("nij,nj->ni", R, r)
    res = compensate(
        cal, p_tool, q_seed, R_target=R, load_scale=load_scale, tol=tol, p_cam=r
    )
    return PoseCompensation(nominal_flange(cal, res.q_ctrl), res)
