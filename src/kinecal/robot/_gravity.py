"""Gravity on a robot's links and tool, and the joint compliance priors it suggests.

:func:`gravity_torques` is the gravity torque about each joint per unit reference weight
(the general link self-weight model's torques, Eqs. 21-25 generalised to N links, from
the nominal DH chain). :func:`compliance_priors` turns its largest value over the joint
ranges into a prior scale for each joint's compliance ``lambda*`` (docs/theory.md,
"Compliance priors from the link masses"): a joint is expected to yield at most about
:data:`PRIOR_DEFLECTION` under the largest gravity load it carries, so its compliance
prior is that angle over that torque.
"""

from __future__ import annotations

import numpy as np

from kinecal.robot._description import RobotDescription, dh_transforms
from kinecal.typing import Float

__all__ = [
    "MAX_COMPLIANCE",
    "PRIOR_DEFLECTION",
    "compliance_priors",
    "finite_limits",
    "gravity_torques",
    "random_joint_poses",
]

# The gravity deflection a joint is expected to show at most [rad]: 0.1 deg, five times
# the typical 0.02 deg of an industrial arm's loaded shoulder, wide enough for a cobot.
PRIOR_DEFLECTION = float(np.radians(0.1))
# The most compliant joint expected [rad/(N m)]: a small wrist gear (1000 N m/rad). It
# bounds the prior of a joint that carries almost no gravity torque.
MAX_COMPLIANCE = 1e-3
_PRIOR_POSES = 400  # poses over which the largest torque is taken (a fixed seed)
_G = 9.80665
# The last robots' priors by id (the robot is kept with them, so an id is not reused
# while its entry lives); descriptions are immutable.
_CACHE: dict[int, tuple[RobotDescription, dict[int, float]]] = {}


def finite_limits(robot: RobotDescription) -> Float:
    """The joint limits (n, 2) [rad or m], +-170 deg or +-0.5 m where a joint has none
    (a URDF's continuous joint): the ranges poses are drawn from."""
    lim = robot.limits.copy()
    wide = np.where(robot.prismatic, 0.5, np.radians(170.0))
    lim[:, 0] = np.where(np.isfinite(lim[:, 0]), lim[:, 0], -wide)
    lim[:, 1] = np.where(np.isfinite(lim[:, 1]), lim[:, 1], wide)
    return lim


def random_joint_poses(
    robot: RobotDescription, n: int, rng: np.random.Generator
) -> Float:
    """``n`` controller poses (n, joints) drawn uniformly within the joint limits (5 %
    margins; +-170 deg or +-0.5 m where a joint has no limit)."""
    lim = finite_limits(robot)
    span = lim[:, 1] - lim[:, 0]
    return rng.uniform(lim[:, 0] + 0.05 * span, lim[:, 1] - 0.05 * span, (n, len(span)))


def gravity_torques(robot: RobotDescription, q_ctrl: Float) -> Float:
    """Gravity torque about each joint (force along a slide) per unit payload weight of
    the robot's link masses and a unit weight at the tool, (N, n) [m or 1].

    From the robot's nominal DH chain: joint j carries every body k >= j and the tool,
    ``tau_j = z_{j-1} · ((p - o_{j-1}) × ĝ) w`` with ``w`` the weight relative to the
    payload's (``robot.payload_kg``, or 1 kg).
    """
    ch = robot.dh_chain()
    th = robot.theta_from_ctrl(q_ctrl)
    N, n = th.shape
    rot = np.where(ch.prismatic, ch.theta_offset, ch.theta_offset + th)
    dd = np.where(ch.prismatic, ch.d + th, ch.d)
    A = dh_transforms(rot, dd, ch.a, ch.alpha)  # (N, n, 4, 4)
    frames = [np.broadcast_to(ch.T_base_0, (N, 4, 4))]
    for i in range(n):  # a loop over joints, not samples
        frames.append(frames[-1] @ A[:, i])
    tool = frames[-1] @ ch.T_n_flange @ robot.T_flange_tool
    g = robot.gravity / np.linalg.norm(robot.gravity)
    m_ref = robot.payload_kg or 1.0
    loads = [(tool[:, :3, 3], 1.0, n)]
    for b in robot.link_masses:
        F = frames[b.frame]
        loads.append(
            (F[:, :3, :3] @ np.asarray(b.com) + F[:, :3, 3], b.mass / m_ref, b.frame)
        )
    tau = np.zeros((N, n))
    for j in range(n):
        z, o = frames[j][:, :3, 2], frames[j][:, :3, 3]
        for p, w, k in loads:
            if k <= j:
                continue  # body k does not move with joint j + 1
            if ch.prismatic[j]:
                tau[:, j] += w * (z @ g)
            else:
                tau[:, j] += w * np.einsum("ni,ni->n", z, np.cross(p - o, g))
    return tau


def compliance_priors(robot: RobotDescription) -> dict[int, float]:
    """Prior standard deviation of each joint's compliance ``lambda*`` [rad/m] (per unit
    reference weight, as the model's), from the robot's link masses:
    :data:`PRIOR_DEFLECTION` over the largest gravity torque the joint carries within its
    limits (:func:`gravity_torques` at 400 seeded poses), by joint number.

    At most :data:`MAX_COMPLIANCE` times the reference weight (a joint that carries
    almost no torque). Empty for a robot without link masses, or whose file states
    ``priors.load_compliance`` (the file's value holds for every joint); slides and
    joints that carry no gravity torque (a vertical first axis) are left out (they
    keep the general prior).
    """
    if not robot.link_masses or ("load", "compliance") in robot.prior_sigma:
        return {}
    hit = _CACHE.get(id(robot))
    if hit is not None and hit[0] is robot:  # a calibration asks about ten times
        return dict(hit[1])
    q = random_joint_poses(robot, _PRIOR_POSES, np.random.default_rng(0))
    tau = np.abs(gravity_torques(robot, q)).max(axis=0)
    cap = MAX_COMPLIANCE * (robot.payload_kg or 1.0) * _G  # lambda* = c |F| [rad/m]
    out = {
        j + 1: min(PRIOR_DEFLECTION / float(tau[j]), cap)
        for j in range(tau.size)
        if tau[j] > 1e-6 * tau.max() and not robot.prismatic[j]
    }
    if len(_CACHE) >= 8:
        _CACHE.pop(next(iter(_CACHE)))
    _CACHE[id(robot)] = (robot, out)
    return dict(out)
