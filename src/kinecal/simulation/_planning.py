"""Pose planning for the paper's two experiments, by vectorised IK on nominal kinematics.

* Experiment 2 (laser tracker, Sec. 5.3): seven tool orientations, each over a 10 x 10 x 10
  grid of tool positions in front of the robot; poses outside the joint limits or reach are
  dropped (the paper kept 6998 of 7000).
* Experiment 1 (3D sensor, Sec. 5.2, Fig. 9): views of the upper halves of the four ceramic
  spheres from all around, with the sphere at the sensor's 115-135 mm working distance on
  its optical axis, and a random turn about that axis.

Poses are planned with the model the user knows (nominal joints, approximate frames); the
robot then really goes wherever the true robot takes those joint angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.geometry import euler_zyx_to_matrix, rot_x, rot_y, rot_z
from kinecal.models import CalibrationModel, solve_ik
from kinecal.typing import Float

__all__ = ["PlannedPoses", "grid_poses", "joint_ranges_deg", "sphere_poses"]


@dataclass(frozen=True)
class PlannedPoses:
    """Reachable poses: controller angles and what each pose is for."""

    q_ctrl: Float  # (N, n) [rad]
    label: np.ndarray  # (N,) int: orientation (exp. 2) or sphere (exp. 1) index
    n_requested: int


def joint_ranges_deg(q_ctrl: Float) -> Float:
    """Range (max - min) covered by each joint [deg], the spread of Fig. 14."""
    return np.degrees(q_ctrl.max(axis=0) - q_ctrl.min(axis=0))


def _flange_down_orientations() -> list[Float]:
    """Seven cam-frame orientations (base frame) for the grid: level, tilted, turned."""
    down = rot_y(np.pi)  # cam z pointing down
    return [
        down,
        rot_x(np.radians(30)) @ down,
        rot_x(np.radians(-30)) @ down,
        rot_y(np.radians(30)) @ down,
        rot_y(np.radians(-30)) @ down,
        down @ rot_z(np.radians(90)),
        rot_y(np.radians(-20)) @ rot_x(np.radians(20)) @ down @ rot_z(np.radians(-60)),
    ]


def grid_poses(
    model: CalibrationModel,
    params: Float,
    *,
    n_side: int = 10,
    center: tuple[float, float, float] = (0.44, 0.0, 0.27),
    size: tuple[float, float, float] = (0.22, 0.44, 0.22),
    orientations: list[Float] | None = None,
    margin_deg: float = 2.0,
) -> PlannedPoses:
    """The experiment-2 layout: orientations x an ``n_side``^3 grid of cam positions.

    Parameters
    ----------
    model, params : nominal model (with the user frame of the set-up) used to plan.
    center, size : the grid box in the robot base frame [m].
    orientations : cam orientations in the base frame (default: seven, see source).
    margin_deg : keep this far from the joint limits.
    """
    ors = orientations or _flange_down_orientations()
    axes = [np.linspace(c - s / 2, c + s / 2, n_side) for c, s in zip(center, size)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    R_b, t_b = model.base_frames(params)
    lim = model.robot.limits.copy()
    lim[:, 0] += np.radians(margin_deg)
    lim[:, 1] -= np.radians(margin_deg)
    qs, labels = [], []
    for k, R_base_cam in enumerate(ors):
        M = grid.shape[0]
        p_user = grid @ R_b[0].T + t_b[0]
        R_user = np.broadcast_to(R_b[0] @ R_base_cam, (M, 3, 3))
        seed = _seed(model, grid, R_base_cam)
        res = solve_ik(
            model, params, p_user, seed, R_target=R_user, limits=lim, max_iter=60
        )
        ok = res.converged
        qs.append(_wrap_turns(res.q_ctrl[ok], lim))
        labels.append(np.full(int(ok.sum()), k))
    return PlannedPoses(
        np.concatenate(qs), np.concatenate(labels), len(ors) * grid.shape[0]
    )


def _wrap_turns(q: Float, lim: Float) -> Float:
    """Move multi-turn joints by whole turns towards zero where the limits allow.

    ``q`` and ``q +- 2 pi`` are the same pose; a program would not spin a wrist a full
    turn between neighbouring points.
    """
    out = q.copy()
    for _ in range(2):
        for sign in (-1.0, 1.0):
            cand = out - sign * 2 * np.pi
            better = (
                (np.abs(cand) < np.abs(out)) & (cand >= lim[:, 0]) & (cand <= lim[:, 1])
            )
            out = np.where(better, cand, out)
    return out


def _seed(model: CalibrationModel, p_base: Float, R_base_cam: Float) -> Float:
    """A plausible elbow-up start: face the target, wrist bent so the tool points its way."""
    n = model.n_joints
    seed = np.zeros((p_base.shape[0], n))
    seed[:, 0] = np.arctan2(p_base[:, 1], p_base[:, 0])
    if n >= 5:
        approach = R_base_cam[:, 2]
        seed[:, 4] = -np.pi / 2 if approach[2] < -0.3 else 0.0
    return seed


def sphere_poses(
    model: CalibrationModel,
    params: Float,
    spheres_user: Float,
    rng: np.random.Generator,
    *,
    per_sphere: int = 50,
    standoff: tuple[float, float] = (0.115, 0.135),
    min_elevation_deg: float = 25.0,
    max_attempts: int = 40,
    margin_deg: float = 2.0,
) -> PlannedPoses:
    """The experiment-1 layout: views of each sphere's upper half from all around.

    The cam frame's z axis (optical axis) points at the sphere centre from a distance in
    ``standoff``; view directions are uniform over the cap above ``min_elevation_deg``
    (measured from the horizontal of the robot base) with a random turn about the axis.
    """
    R_b, t_b = model.base_frames(params)
    centres_base = (spheres_user - t_b[0]) @ R_b[0]
    lim = model.robot.limits.copy()
    lim[:, 0] += np.radians(margin_deg)
    lim[:, 1] -= np.radians(margin_deg)
    qs, labels = [], []
    sin_lo = np.sin(np.radians(min_elevation_deg))
    for k, c in enumerate(centres_base):
        got: list[Float] = []
        n_got = 0
        for _ in range(max_attempts):
            m = 4 * per_sphere
            z = rng.uniform(sin_lo, 1.0, m)  # uniform on the spherical cap
            az = rng.uniform(-np.pi, np.pi, m)
            v = np.column_stack(
                [np.sqrt(1 - z * z) * np.cos(az), np.sqrt(1 - z * z) * np.sin(az), z]
            )
            d = rng.uniform(*standoff, m)
            cam = c + v * d[:, None]
            z_cam = -v
            x0 = np.cross(z_cam, [0.0, 0.0, 1.0])
            x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
            y0 = np.cross(z_cam, x0)
            R0 = np.stack([x0, y0, z_cam], axis=2)
            R_base_cam = R0 @ euler_zyx_to_matrix(
                np.column_stack(
                    [rng.uniform(-np.pi, np.pi, m), np.zeros(m), np.zeros(m)]
                )
            )
            seed = _seed(model, cam, np.eye(3))
            seed[:, 4] = -np.pi / 2
            res = solve_ik(
                model,
                params,
                cam @ R_b[0].T + t_b[0],
                seed,
                R_target=R_b[0] @ R_base_cam,
                limits=lim,
                max_iter=60,
            )
            ok = np.flatnonzero(res.converged)
            got.append(_wrap_turns(res.q_ctrl[ok], lim))
            n_got += ok.size
            if n_got >= per_sphere:
                break
        q = np.concatenate(got)[:per_sphere]
        qs.append(q)
        labels.append(np.full(q.shape[0], k))
    return PlannedPoses(
        np.concatenate(qs), np.concatenate(labels), per_sphere * len(centres_base)
    )
