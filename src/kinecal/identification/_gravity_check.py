"""Does a calibration without link self-weight terms leave gravity-like residuals?

A robot file with neither a lumped ``self_weight`` layout nor ``link_masses`` is
calibrated without link terms; if the arm's own weight bends it, the residuals keep the
pattern of a deflection of each joint in proportion to the weight of the links beyond it.
The check regresses the residuals on that pattern, with the weights unknown: a column
``J_j(q) t_jk(q)`` for every joint j and every DH frame k > j, ``J_j`` the effect of joint
j's angle on the point and ``t_jk = z_{j-1} · ((o_k - o_{j-1}) × ĝ)`` the gravity torque
of a unit mass at frame k's origin. A significant fit that explains a good share of the
residuals is reported (``systematic_residuals``).
"""

from __future__ import annotations

import math

import numpy as np

from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._measurements import Measurements
from kinecal.robot import RobotDescription, dh_transforms
from kinecal.typing import Float

__all__ = ["gravity_check", "unit_mass_torques"]

# Report when the gravity pattern explains this share of the residual sum of squares
# and the regression is significant at this level.
_SHARE = 0.25
_ALPHA = 1e-6


def _chi2_sf(x: float, k: int) -> float:
    """Survival function of chi-square with k degrees of freedom (Wilson-Hilferty; the
    regression F statistic times its rank, for many residual degrees of freedom; no
    scipy.stats, which would load numpy.ma into every calibration)."""
    if x <= 0:
        return 1.0
    v = 2.0 / (9.0 * k)
    z = ((x / k) ** (1.0 / 3.0) - (1.0 - v)) / math.sqrt(v)
    return 0.5 * math.erfc(z / math.sqrt(2.0))


def unit_mass_torques(robot: RobotDescription, q_ctrl: Float) -> Float:
    """Torque ``t[n, j, k]`` of a unit weight at the origin of DH frame k + 1 about the
    axis of joint j + 1 (zero for k < j, and along the axis for a slide), (N, n, n) [m]."""
    ch = robot.dh_chain()
    th = robot.theta_from_ctrl(np.asarray(q_ctrl, np.float64))
    N, n = th.shape
    rot = np.where(ch.prismatic, ch.theta_offset, ch.theta_offset + th)
    dd = np.where(ch.prismatic, ch.d + th, ch.d)
    A = dh_transforms(rot, dd, ch.a, ch.alpha)
    T = np.broadcast_to(ch.T_base_0, (N, 4, 4))
    frames = [T]
    for i in range(n):  # a loop over joints, not samples
        frames.append(frames[-1] @ A[:, i])
    g = robot.gravity / np.linalg.norm(robot.gravity)
    out = np.zeros((N, n, n))
    for j in range(n):
        z, o = frames[j][:, :3, 2], frames[j][:, :3, 3]
        for k in range(j, n):
            if ch.prismatic[j]:
                out[:, j, k] = z @ g
            else:
                lever = frames[k + 1][:, :3, 3] - o
                out[:, j, k] = np.einsum("ni,ni->n", z, np.cross(lever, g))
    return out


def gravity_check(result: object, meas: Measurements) -> Diagnostic | None:
    """A ``systematic_residuals`` warning when ``result`` (a calibration with the payload
    compliance but no link terms, of a robot with no self-weight layout) leaves
    gravity-like residuals."""
    cal = result.calibrated  # type: ignore[attr-defined]
    robot = cal.model.robot
    if robot.self_weight is not None or robot.link_bodies:
        return None
    spec = cal.model.spec
    if spec.link != "none" or not spec.load or meas.kind == "sensor":
        return None  # (a model without the payload term misses that gravity as well)
    m = cal.align(meas)
    r = cal.predict(m).raw_position  # (N, 3)
    inputs = m.model_inputs(cal.reference_payload_kg)
    J = cal.model.joint_jacobian(cal.params, inputs)[:, :3, :]  # (N, 3, n)
    t = unit_mass_torques(robot, meas.q_ctrl)  # (N, n, n)
    X = np.einsum("nij,njk->nijk", J, t).reshape(r.size, -1)
    X = X[:, np.linalg.norm(X, axis=0) > 1e-12 * max(np.abs(X).max(), 1e-300)]
    if X.shape[1] == 0 or r.size <= 2 * X.shape[1]:
        return None
    coef, *_ = np.linalg.lstsq(X, r.ravel(), rcond=1e-10)
    fit = X @ coef
    rank = int(np.linalg.matrix_rank(X, tol=1e-10 * np.linalg.norm(X, 2)))
    ss_r, ss_fit = float(r.ravel() @ r.ravel()), float(fit @ fit)
    share = ss_fit / ss_r if ss_r > 0 else 0.0
    dof = r.size - rank
    if dof < 1 or share >= 1.0:
        return None
    p = _chi2_sf(rank * (share / rank) / ((1 - share) / dof), rank)
    if share < _SHARE or p > _ALPHA:
        return None
    rms_after = np.sqrt((ss_r - ss_fit) / len(r)) * 1e3
    return Diagnostic(
        "systematic_residuals",
        f"the residuals follow the gravity torques of the links ({100 * share:.0f} % "
        f"of them; RMS {np.sqrt(ss_r / len(r)) * 1e3:.4f} mm, {rms_after:.4f} mm "
        f"without that part), but robot {robot.name} has no self-weight layout: give "
        "it link_masses (kinecal import-urdf reads them from a URDF's inertials) or a "
        "self_weight section (docs/files.md) and calibrate again.",
        stage="gravity check",
    )
