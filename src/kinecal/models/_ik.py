"""Vectorised numerical inverse kinematics on a calibration model.

Two methods share :func:`solve_ik`: this module's plain damped least squares ('dls', pose
planning from rough seeds) and :mod:`kinecal.models._ik_lm` ('lm', compensation).

Solves ``model(q_ctrl) = target`` for N targets at once by damped least squares
(Levenberg-Marquardt per target): each iteration evaluates the model with every error term
and takes ``dq = C^-1 J^T (J J^T + lambda^2 I)^-1 e`` with the geometric Jacobian ``J``
(w.r.t. the kinematic angles; the small dependence of the compliance terms on q is left out
of the Jacobian, not out of the residual, so the converged solution is exact).

Orientation errors are weighted by a characteristic length so a 1 mrad error counts like
``length`` x 1 mrad of position error.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from kinecal.geometry import so3_log
from kinecal.models._ik_lm import IKResult, solve_ik_lm
from kinecal.models._inputs import ModelInputs
from kinecal.models._model import CalibrationModel
from kinecal.typing import Float

__all__ = ["IKResult", "solve_ik"]


def solve_ik(
    model: CalibrationModel,
    params: Float,
    p_target: Float,
    q_seed: Float,
    *,
    R_target: Float | None = None,
    set_index: np.ndarray | None = None,
    marker_index: np.ndarray | None = None,
    load_scale: Float | None = None,
    limits: Float | None = None,
    tol_position: float = 1e-10,
    tol_rotation: float = 1e-9,
    max_iter: int = 50,
    length: float = 0.5,
    method: Literal["dls", "lm"] = "dls",
    point_only: np.ndarray | bool | None = None,
) -> IKResult:
    """Controller angles that put the cam origin on ``p_target`` (and cam axes on ``R_target``).

    Parameters
    ----------
    model, params : the model to invert (nominal or calibrated).
    p_target : (N, 3) target points in the user frame [m].
    q_seed : (N, n) starting controller angles (they pick the IK branch).
    R_target : (N, 3, 3), optional
        Target orientations of the cam frame. When omitted, the orientation the model gives
        at the seed is kept (a position-only target keeps the program's tool orientation).
    set_index, marker_index, load_scale : per-target model inputs (see ModelInputs).
    limits : (n, 2) controller joint limits [rad]; default the robot's.
    tol_position, tol_rotation : convergence tolerances [m], [rad].
    length : characteristic length weighting orientation errors [m].
    method : {'dls', 'lm'}
        'dls': plain damped least squares with the geometric Jacobian, for rough seeds
        (pose planning: the simulated experiments are defined by its results, so it
        stays as it is). 'lm': Levenberg-Marquardt with a line search, a Newton polish
        on the exact Jacobian, point targets and per-target diagnostics, for seeds near
        the solution (compensation; :func:`kinecal.models._ik_lm.solve_ik_lm`).
    point_only : with 'lm': targets whose orientation is met only where it can be met
        together with the position (default: all when ``R_target`` is omitted).
    """
    if method == "lm":
        return solve_ik_lm(
            model,
            params,
            p_target,
            q_seed,
            R_target=R_target,
            point_only=point_only,
            set_index=set_index,
            marker_index=marker_index,
            load_scale=load_scale,
            limits=limits,
            tol_position=tol_position,
            tol_rotation=tol_rotation,
            max_iter=max_iter,
            length=length,
        )
    if method != "dls":
        raise ValueError(f"method must be 'dls' or 'lm'; got {method!r}.")
    q = np.array(q_seed, dtype=np.float64)
    lim = model.robot.limits if limits is None else np.asarray(limits, dtype=np.float64)
    dls = _Targets(
        model,
        params,
        p_target,
        R_target,
        q,
        set_index,
        marker_index,
        load_scale,
        length,
    )
    it = _iterate(dls, q, lim, tol_position, tol_rotation, max_iter)
    ep, er = dls.errors(q, np.arange(dls.n))
    e_pos = np.linalg.norm(ep, axis=1)
    e_rot = np.linalg.norm(er, axis=1)
    within = np.all((q >= lim[:, 0] - 1e-12) & (q <= lim[:, 1] + 1e-12), axis=1)
    conv = (
        within
        & (e_pos <= max(tol_position * 10, 1e-9))
        & (e_rot <= max(tol_rotation * 10, 1e-8))
    )
    return IKResult(q, e_pos, e_rot, within, conv, it)


class _Targets:
    """The 'dls' targets: the model, its parameters, the target poses and the per-target
    model inputs."""

    def __init__(
        self,
        model: CalibrationModel,
        params: Float,
        p_target: Float,
        R_target: Float | None,
        q: Float,
        set_index: np.ndarray | None,
        marker_index: np.ndarray | None,
        load_scale: Float | None,
        length: float,
    ) -> None:
        self.model, self.params, self.length = model, params, length
        self.set_index, self.marker_index = set_index, marker_index
        self.load_scale = load_scale
        self.n = N = q.shape[0]
        self.pt = np.asarray(p_target, dtype=np.float64).reshape(N, 3)
        if R_target is None:  # the orientation the model gives at the seed
            out = model.evaluate(params, self.inputs(q, np.arange(N)), orientation=True)
            R_t = out.R_user_cam
        else:
            R_t = np.asarray(R_target, dtype=np.float64).reshape(N, 3, 3)
        assert R_t is not None
        self.R_t: Float = R_t

    def inputs(self, qq: Float, rows: np.ndarray) -> ModelInputs:
        """Model inputs of the given rows at joint values qq (one per row)."""
        return ModelInputs.make(
            qq,
            set_index=None if self.set_index is None else self.set_index[rows],
            marker_index=None if self.marker_index is None else self.marker_index[rows],
            load_scale=None if self.load_scale is None else self.load_scale[rows],
        )

    def errors(self, qq: Float, rows: np.ndarray) -> tuple[Float, Float]:
        """Position and orientation errors (M, 3) of the rows at ``qq[rows]``."""
        out = self.model.evaluate(
            self.params, self.inputs(qq[rows], rows), orientation=True
        )
        assert out.R_user_cam is not None
        ep = self.pt[rows] - out.p_user
        er = so3_log(self.R_t[rows] @ np.swapaxes(out.R_user_cam, 1, 2))
        return ep, er

    def jacobian(self, qa: Float, rows: np.ndarray) -> Float:
        """The geometric Jacobian (M, 6, n) w.r.t. q_ctrl, orientation rows weighted."""
        J = self.model.joint_jacobian(
            self.params, self.inputs(qa, rows)
        )  # w.r.t. theta
        J = J @ self.model.robot.coupling  # w.r.t. q_ctrl
        J[:, 3:, :] *= self.length
        return J


def _iterate(
    dls: _Targets,
    q: Float,
    lim: Float,
    tol_position: float,
    tol_rotation: float,
    max_iter: int,
) -> int:
    """Damped least-squares iterations on ``q`` (in place) until every target has
    converged or stalled; the number of iterations."""
    N = dls.n
    lam2 = np.full(N, 1e-6)
    active = np.ones(N, dtype=bool)
    e_pos = np.full(N, np.inf)
    e_rot = np.full(N, np.inf)
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count is returned
        rows = np.flatnonzero(active)
        if rows.size == 0:
            break
        qa = q[rows]
        ep, er = dls.errors(q, rows)
        e_pos[rows] = np.linalg.norm(ep, axis=1)
        e_rot[rows] = np.linalg.norm(er, axis=1)
        done = (e_pos[rows] <= tol_position) & (e_rot[rows] <= tol_rotation)
        active[rows[done]] = False
        keep = ~done
        if not np.any(keep):
            break
        rows, qa, ep, er = rows[keep], qa[keep], ep[keep], er[keep]
        _damped_step(dls, q, lam2, active, rows, qa, ep, er, lim)
    return it


def _damped_step(
    dls: _Targets,
    q: Float,
    lam2: Float,
    active: np.ndarray,
    rows: np.ndarray,
    qa: Float,
    ep: Float,
    er: Float,
    lim: Float,
) -> None:
    """One damped step of the ``rows`` (``q``, ``lam2`` and ``active`` updated in
    place), with the damping raised where a step does not reduce the error."""
    length = dls.length
    J = dls.jacobian(qa, rows)  # (M, 6, n)
    e = np.concatenate([ep, er * length], axis=1)  # (M, 6)
    JJt = J @ np.swapaxes(J, 1, 2)
    cost = np.sum(e * e, axis=1)
    for _ in range(8):
        A = JJt + lam2[rows, None, None] * np.eye(6)
        y = np.linalg.solve(A, e[:, :, None])[:, :, 0]
        dq = np.einsum("mji,mj->mi", J, y)  # Eq. (29), every joint, damped
        q_new = np.clip(qa + dq, lim[:, 0], lim[:, 1])
        q_try = q.copy()
        q_try[rows] = q_new
        ep2, er2 = dls.errors(q_try, rows)
        cost2 = np.sum(ep2 * ep2, axis=1) + np.sum((er2 * length) ** 2, axis=1)
        better = cost2 < cost
        q[rows[better]] = q_new[better]
        lam2[rows[better]] = np.maximum(lam2[rows[better]] * 0.1, 1e-12)
        worse = ~better
        if not np.any(worse):
            break
        lam2[rows[worse]] *= 10.0
        rows, qa, e, J, JJt, cost = (
            rows[worse],
            qa[worse],
            e[worse],
            J[worse],
            JJt[worse],
            cost[worse],
        )
        if np.all(lam2[rows] > 1e6):
            active[rows] = False  # stuck: at a limit or singular
            break
