"""Inverse kinematics for compensation: LM with a line search and a Newton polish.

For N targets at once, find controller angles ``q`` with ``model(q) = target`` on the
model's full forward map (kinematics, transmission errors and compliance: the residual is
always the model's own):

.. math::
    r(q) = [e_p; w e_o], \\qquad e_p = p_{target} - p_{user}(q), \\quad
    e_o = \\log(R_{target} R_{user,cam}(q)^T)

(``w``, ``length``, weighs 1 rad of orientation like ``w`` metres of position). A *pose*
target must meet both. A *point* target (a position; the orientation wanted is the seed's)
must meet the position, and meets the orientation where the pose task is well conditioned;
near a singular pose (the stretched elbow, a straight wrist) the orientation is given up
along the nearly singular directions, and the tool turns a little instead of the joints
moving a lot.

1. Damped least squares (Levenberg-Marquardt per target) on ``[e_p; w e_o]`` with a
   backtracking line search and the geometric Jacobian (``joint_jacobian`` times the
   coupling). That Jacobian omits how the small compliance and transmission terms change
   with ``q``; it is computed again only when a full step fails to shrink the residual
   ten-fold (a chord method: one Jacobian serves most targets to the end). Point
   targets leave out the directions whose singular value is below 2 % of the largest
   (a truncated pseudo-inverse). A target stops after three steps that barely help.
2. Newton polish, where phase 1 left the task unmet: the same damped step, nearly
   undamped, with the exact Jacobian of the full model (central differences of the
   forward map), which converges quadratically next to singular poses too. Point
   targets drop the orientation here (minimum-norm steps on the position alone).

Joint limits are a box: a joint at a limit whose step points out of it is held for the
step (projected, active-set steps). Per target the result has the remaining errors, the
condition number of the task Jacobian at the solution and the joint holding it at a limit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from kinecal.geometry import so3_log
from kinecal.models._inputs import ModelInputs
from kinecal.models._model import CalibrationModel
from kinecal.typing import ArrayLike, Float

__all__ = ["IKResult", "solve_ik_lm"]

_ALPHAS = (1.0, 0.5, 0.25, 0.1)  # line search step lengths
_LAMBDA0 = 1e-6  # initial damping, relative to the mean squared Jacobian entry
_LAMBDA_MIN = 1e-14
_LAMBDA_MAX = 1e6
_LAMBDA_POLISH = 1e-10  # the polish starts nearly undamped (Newton)
# Point targets, phase 1: directions of the weighted Jacobian with a singular value below
# this fraction of the largest are left out (near the stretched elbow or a straight
# wrist, the orientation is not chased with large joint motion).
_POINT_CUT = 0.02
_FD_STEP = 2e-6  # [rad, m] central differences of the forward map
_AT_LIMIT = 1e-12  # [rad, m]


@dataclass(frozen=True)
class IKResult:
    """Joint solutions and how well they reach the targets.

    Attributes
    ----------
    q_ctrl : (N, n) controller joint values [rad; m for prismatic joints].
    position_error : (N,) remaining position error [m].
    rotation_error : (N,) remaining orientation error [rad].
    within_limits : (N,) bool, every joint inside its limits.
    converged : (N,) bool, the primary task met (position, and orientation for pose
        targets, below tolerance) within the limits.
    iterations : int, the largest number of iterations any target needed.
    cond : (N,) or None, condition number of the task Jacobian at the solution (the
        position rows for point targets; position and ``length``-weighted orientation
        rows for pose targets); inf where it is singular.
    limit_joint : (N,) int or None, 0-based joint at a limit that blocks an unconverged
        target (its last step pointed out of the box), -1 for none.
    n_iter : (N,) int or None, iterations per target (both phases).

    The last three are None from ``solve_ik(method="dls")``.
    """

    q_ctrl: Float
    position_error: Float
    rotation_error: Float
    within_limits: np.ndarray
    converged: np.ndarray
    iterations: int
    cond: Float | None = None
    limit_joint: np.ndarray | None = None
    n_iter: np.ndarray | None = None


class _Problem:
    """The targets, their model inputs and the two Jacobians."""

    def __init__(
        self,
        model: CalibrationModel,
        params: Float,
        p_target: Float,
        R_target: Float,
        point: np.ndarray,
        set_index: np.ndarray | None,
        marker_index: np.ndarray | None,
        load_scale: Float | None,
        length: float,
        p_cam: Float | None = None,
    ) -> None:
        self.model = model
        self.params = params
        self.p_t = p_target
        self.R_t = R_target
        self.point = point
        self.si = set_index
        self.mi = marker_index
        self.ls = load_scale
        self.p_cam = p_cam
        self.length = length
        self.C = model.robot.coupling

    def inputs(self, q: Float, rows: np.ndarray, repeat: int = 1) -> ModelInputs:
        """Model inputs of ``rows`` at joint values ``q`` (len(rows) * repeat, n), each
        row's inputs repeated ``repeat`` times in a row."""

        def pick(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else np.repeat(a[rows], repeat, axis=0)

        return ModelInputs.make(
            q,
            set_index=pick(self.si),
            marker_index=pick(self.mi),
            load_scale=pick(self.ls),
            p_cam=pick(self.p_cam),
        )

    def errors(self, q: Float, rows: np.ndarray) -> tuple[Float, Float]:
        """Position (M, 3) [m] and orientation (M, 3) [rad] errors of ``rows`` at q (M, n)."""
        out = self.model.evaluate(self.params, self.inputs(q, rows), orientation=True)
        assert out.R_user_cam is not None
        e_p = self.p_t[rows] - out.p_user
        e_o = so3_log(self.R_t[rows] @ np.swapaxes(out.R_user_cam, 1, 2))
        return e_p, e_o

    def jac_geometric(self, q: Float, rows: np.ndarray) -> Float:
        """``d [p; orientation] / d q_ctrl`` (M, 6, n) with the error terms held fixed."""
        J = self.model.joint_jacobian(self.params, self.inputs(q, rows))
        return np.asarray(J @ self.C)

    def jac_exact(self, q: Float, rows: np.ndarray) -> Float:
        """The full model's ``d [p; orientation] / d q_ctrl`` (M, 6, n) by central
        differences (every error term moving with q)."""
        M, n = q.shape
        h = _FD_STEP
        steps = np.concatenate([np.eye(n), -np.eye(n)]) * h  # (2n, n)
        qq = (q[:, None, :] + steps[None]).reshape(M * 2 * n, n)
        out = self.model.evaluate(
            self.params, self.inputs(qq, rows, 2 * n), orientation=True
        )
        assert out.R_user_cam is not None
        p = out.p_user.reshape(M, 2, n, 3)
        R = out.R_user_cam.reshape(M, 2, n, 3, 3)
        J = np.empty((M, 6, n))
        J[:, :3] = np.swapaxes(p[:, 0] - p[:, 1], 1, 2) / (2 * h)
        w = so3_log(R[:, 0] @ np.swapaxes(R[:, 1], -1, -2))  # (M, n, 3)
        J[:, 3:] = np.swapaxes(w, 1, 2) / (2 * h)
        return J


def _damped_step(A: Float, r: Float, lam: Float, free: np.ndarray, cut: Float) -> Float:
    """Damped least-squares step ``A^T (A A^T + mu^2 I)^-1 r`` per row (M, n) for the
    task Jacobian A (M, 6, n) and residual r (M, 6), joints outside ``free`` (M, n) held;
    ``mu^2 = lam * sum(A**2) / 6`` (damping relative to the Jacobian's size).

    Rows with ``cut`` > 0 (M,) leave out the directions whose singular value is below
    ``cut`` times the largest (a truncated pseudo-inverse): a point target does not
    chase its orientation along a nearly singular direction with large joint motion.
    Only rows that may be that ill-conditioned (by the cheap Frobenius bound
    ``||S|| ||S^-1|| >= cond(S)``, ``S = A A^T``) get a singular value decomposition.
    """
    Af = A * free[:, None, :]
    S = Af @ np.swapaxes(Af, 1, 2)
    scale = np.trace(S, axis1=1, axis2=2) / 6 + 1e-300
    mu2 = lam * scale
    Sinv = np.linalg.inv(S + mu2[:, None, None] * np.eye(6))
    dq = np.einsum("mji,mjk,mk->mi", Af, Sinv, r)
    check = cut > 0.0
    if check.any():
        bound = np.linalg.norm(S[check], axis=(1, 2)) * np.linalg.norm(
            Sinv[check], axis=(1, 2)
        )
        rows = np.flatnonzero(check)[bound > cut[check] ** -2]
        if rows.size:
            U, sv, Vt = np.linalg.svd(Af[rows], full_matrices=False)
            keep = sv >= cut[rows, None] * sv[:, :1]
            filt = np.where(keep, sv / (sv * sv + mu2[rows, None]), 0.0)
            coef = np.einsum("mji,mj->mi", U, r[rows]) * filt
            dq[rows] = np.einsum("mki,mk->mi", Vt, coef)
    return dq


def solve_ik_lm(
    model: CalibrationModel,
    params: ArrayLike,
    p_target: ArrayLike,
    q_seed: ArrayLike,
    *,
    R_target: ArrayLike | None = None,
    point_only: ArrayLike | bool | None = None,
    set_index: np.ndarray | None = None,
    marker_index: np.ndarray | None = None,
    load_scale: Float | None = None,
    limits: ArrayLike | None = None,
    p_cam: ArrayLike | None = None,
    tol_position: float = 1e-10,
    tol_rotation: float = 1e-9,
    max_iter: int = 50,
    polish_iter: int = 8,
    length: float = 0.5,
) -> IKResult:
    """Controller angles that put the cam origin on ``p_target`` (and the cam axes on
    ``R_target``), on the model's full forward map.

    Parameters
    ----------
    model, params : the model to invert (nominal or calibrated) and its parameters (P,).
    p_target : (N, 3) target points in the user frame [m].
    q_seed : (N, n) starting controller angles (they pick the IK branch) [rad, m].
    R_target : (N, 3, 3), optional
        Target orientations of the cam frame in the user frame. When omitted, the
        orientation the model gives at the seed is wanted, and every target is a point
        target.
    point_only : bool or (N,) bool, optional
        Point targets: the position must be met; the orientation is met where the pose
        task is well conditioned. Near a singular pose, the directions of the weighted
        pose Jacobian with a singular value below 2 % of the largest are left out of
        the first phase, and the polish meets the position with minimum-norm steps:
        the tool turns a little instead of the joints moving a lot. Default: True where
        ``R_target`` is omitted, False where it is given.
    set_index, marker_index, load_scale : (N,) per-target model inputs (see ModelInputs).
    limits : (n, 2) controller joint limits [rad, m]; default the robot's.
    p_cam : (N, 3), optional the point of the cam frame put on ``p_target`` [m].
    tol_position, tol_rotation : the task is met below these [m], [rad].
    max_iter : iterations of the damped least-squares phase.
    polish_iter : iterations of the Newton polish with the exact Jacobian.
    length : characteristic length weighting orientation errors [m].

    Returns
    -------
    IKResult
    """
    p = np.asarray(params, dtype=np.float64)
    q = np.array(q_seed, dtype=np.float64, ndmin=2)
    N, n = q.shape
    if n != model.n_joints:
        raise ValueError(
            f"q_seed must have shape (N, {model.n_joints}); got {q.shape}."
        )
    pt = np.asarray(p_target, dtype=np.float64).reshape(N, 3)
    lim = (
        model.robot.limits
        if limits is None
        else np.asarray(limits, dtype=np.float64).reshape(n, 2)
    )
    q = np.clip(q, lim[:, 0], lim[:, 1])
    if point_only is None:
        point = np.full(N, R_target is None)
    else:
        point = np.broadcast_to(np.asarray(point_only, dtype=bool), (N,)).copy()
    prob = _Problem(
        model,
        p,
        pt,
        np.zeros((N, 3, 3)),
        point,
        set_index,
        marker_index,
        load_scale,
        length,
        p_cam if p_cam is None else np.asarray(p_cam, np.float64).reshape(N, 3),
    )
    errors = None
    if R_target is None:  # the seed's orientation
        out = model.evaluate(p, prob.inputs(q, np.arange(N)), orientation=True)
        assert out.R_user_cam is not None
        prob.R_t = out.R_user_cam
        errors = (pt - out.p_user, np.zeros((N, 3)))
    else:
        prob.R_t = np.asarray(R_target, dtype=np.float64).reshape(N, 3, 3)

    state = _State(prob, q, lim, tol_position, tol_rotation, errors)
    # 1. Position and orientation together, with the geometric Jacobian.
    w_o = np.full(N, length)
    cuts = np.where(point, _POINT_CUT, 0.0)
    it1 = state.run(prob.jac_geometric, max_iter, w_o, cuts)
    # 2. Newton polish with the exact Jacobian where the task is not met yet; point
    # targets drop the orientation (met wherever phase 1 could meet both).
    w_o[point] = 0.0
    state.restart(~state.met)
    it2 = state.run(prob.jac_exact, polish_iter, w_o, np.zeros(N))
    return state.result(it1 + it2)


class _State:
    """Per-target iterates of :func:`solve_ik` (all arrays over the N targets)."""

    def __init__(
        self,
        prob: _Problem,
        q: Float,
        lim: Float,
        tol_p: float,
        tol_r: float,
        errors: tuple[Float, Float] | None = None,
    ) -> None:
        N, n = q.shape
        self.prob = prob
        self.q = q
        self.lim = lim
        self.tol_p = tol_p
        self.tol_r = tol_r
        rows = np.arange(N)
        self.e_p, self.e_o = prob.errors(q, rows) if errors is None else errors
        self.lam = np.full(N, _LAMBDA0)
        self.fails = np.zeros(N, np.intp)
        self.n_iter = np.zeros(N, np.intp)
        self.J = np.full((N, 6, n), np.nan)  # the last Jacobian of each target
        self.fresh = np.zeros(N, bool)  # J may serve the next step
        self.push = np.zeros((N, n))  # the last unconstrained step (limit diagnosis)
        self.met = np.zeros(N, bool)
        self.both = np.zeros(N, bool)
        self._update(rows)
        self.active = ~self.both

    def _update(self, rows: np.ndarray) -> None:
        """Which rows meet their task (``met``) and both position and orientation."""
        ok_p = np.linalg.norm(self.e_p[rows], axis=1) <= self.tol_p
        ok_o = np.linalg.norm(self.e_o[rows], axis=1) <= self.tol_r
        self.both[rows] = ok_p & ok_o
        self.met[rows] = ok_p & (ok_o | self.prob.point[rows])

    def restart(self, rows_mask: np.ndarray) -> None:
        self.active = rows_mask.copy()
        self.lam[rows_mask] = _LAMBDA_POLISH
        self.fresh[rows_mask] = False
        self.fails[rows_mask] = 0

    def run(
        self,
        jac: Callable[[Float, np.ndarray], Float],
        max_iter: int,
        w_o: Float,
        cuts: Float,
    ) -> int:
        """Damped steps with a backtracking line search on the active rows, for the
        residual ``[e_p; w_o e_o]``; returns the iterations done. A row stops when its
        residual is met, or after a few iterations without any improvement."""
        lo, hi = self.lim[:, 0], self.lim[:, 1]
        it = 0
        for it in range(1, max_iter + 1):
            rows = np.flatnonzero(self.active)
            if rows.size == 0:
                return it - 1
            q0 = self.q[rows]
            w = w_o[rows, None]
            stale = rows[~self.fresh[rows]]
            if stale.size:
                self.J[stale] = jac(self.q[stale], stale)
                self.fresh[stale] = True
            J = self.J[rows]
            A = J.copy()
            A[:, 3:] *= w[:, :, None]
            r = np.concatenate([self.e_p[rows], self.e_o[rows] * w], axis=1)
            cost = np.einsum("mi,mi->m", r, r)
            lam = self.lam[rows]
            cut = cuts[rows]
            dq = _damped_step(A, r, lam, np.ones(q0.shape, bool), cut)
            self.push[rows] = dq
            # Joints at a limit with the step pointing out of the box are held.
            blocked = ((q0 <= lo + _AT_LIMIT) & (dq < 0)) | (
                (q0 >= hi - _AT_LIMIT) & (dq > 0)
            )
            if blocked.any():
                dq = _damped_step(A, r, lam, ~blocked, cut)
            self.n_iter[rows] += 1
            taken = np.full(rows.size, np.nan)
            pending = np.arange(rows.size)
            for alpha in _ALPHAS:
                k = rows[pending]
                q_try = np.clip(q0[pending] + alpha * dq[pending], lo, hi)
                ep, eo = self.prob.errors(q_try, k)
                c = np.sum(ep * ep, axis=1) + np.sum((eo * w[pending]) ** 2, axis=1)
                ok = c < (1.0 - 1e-9) * cost[pending]
                self.q[k[ok]] = q_try[ok]
                self.e_p[k[ok]] = ep[ok]
                self.e_o[k[ok]] = eo[ok]
                taken[pending[ok]] = alpha
                pending = pending[~ok]
                if pending.size == 0:
                    break
            # The Jacobian is kept while full steps contract the residual ten-fold (a
            # chord / simplified Newton method), and computed again otherwise.
            cost_new = np.sum(self.e_p[rows] ** 2, axis=1) + np.sum(
                (self.e_o[rows] * w) ** 2, axis=1
            )
            self.fresh[rows] = (taken == 1.0) & (cost_new <= 0.01 * cost)
            lam = np.where(taken == 1.0, lam * 0.1, lam * 10.0)
            lam = np.where(np.isnan(taken), lam * 10.0, lam)
            self.lam[rows] = np.clip(lam, _LAMBDA_MIN, _LAMBDA_MAX)
            # A row stops after steps that barely help: it sits at the best compromise
            # of position and orientation (point targets near a singular pose), or
            # converges too slowly for the chord Jacobian (the polish takes over).
            slow = cost_new > 0.25 * cost
            self.fails[rows] = np.where(slow, self.fails[rows] + 1, 0)
            self._update(rows)
            task_met = np.where(w_o[rows] > 0, self.both[rows], self.met[rows])
            stop = task_met | (self.fails[rows] >= 3) | (self.lam[rows] >= _LAMBDA_MAX)
            self.active[rows[stop]] = False
        return it

    # ---------------------------------------------------------------- result
    def result(self, iterations: int) -> IKResult:
        prob, q, lim = self.prob, self.q, self.lim
        N, n = q.shape
        missing = np.flatnonzero(np.isnan(self.J[:, 0, 0]))
        if missing.size:
            self.J[missing] = prob.jac_geometric(q[missing], missing)
        A = self.J.copy()
        A[:, 3:] *= prob.length
        cond = np.empty(N)
        pose = ~prob.point
        for mask, Am in ((pose, A), (prob.point, A[:, :3])):
            if mask.any():
                s = np.linalg.svd(Am[mask], compute_uv=False)
                k = min(Am.shape[1], n)
                with np.errstate(divide="ignore"):
                    cond[mask] = s[:, 0] / s[:, k - 1]
        ep = np.linalg.norm(self.e_p, axis=1)
        eo = np.linalg.norm(self.e_o, axis=1)
        within = np.all((q >= lim[:, 0] - 1e-12) & (q <= lim[:, 1] + 1e-12), axis=1)
        converged = within & self.met
        at_lo = (q <= lim[:, 0] + 1e-9) & (self.push < 0)
        at_hi = (q >= lim[:, 1] - 1e-9) & (self.push > 0)
        blocking = (at_lo | at_hi) & ~converged[:, None]
        strength = np.where(blocking, np.abs(self.push), -1.0)
        limit_joint = np.where(blocking.any(axis=1), np.argmax(strength, axis=1), -1)
        return IKResult(
            q, ep, eo, within, converged, iterations, cond, limit_joint, self.n_iter
        )
