"""Simulated sensor sessions: calibration views, plane-target poses and sphere scans."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.geometry import so3_exp
from kinecal.sensor._render import (
    ChessboardTarget,
    PlaneSurface,
    Scene,
    SphereSurface,
    StripeRenderer,
    render_chessboard,
)
from kinecal.sensor._sensor import Sensor
from kinecal.typing import Float

__all__ = [
    "CalibrationSession",
    "board_views",
    "simulate_calibration",
    "sphere_scene",
]


def board_views(
    rng: np.random.Generator,
    n: int,
    target: ChessboardTarget | None = None,
    *,
    distance: tuple[float, float] = (0.115, 0.135),
    tilt_deg: float = 30.0,
    spread: tuple[float, float] = (0.075, 0.06),
) -> Float:
    """Poses (n, 4, 4) of the chessboard in the camera frame, centred in the view.

    Tilts are spread in direction (a golden-angle spiral) so that Zhang's method sees the
    board from many sides, the condition for a well-determined focal length; the board
    centre moves over a 3 x 3 grid of directions ``spread`` (x, y per metre of depth).
    """
    tgt = target or ChessboardTarget()
    centre = np.array([(tgt.cols - 1) / 2, (tgt.rows - 1) / 2, 0.0]) * tgt.square
    out = np.zeros((n, 4, 4))
    for k in range(n):
        phi = k * 2.399963229728653
        mag = np.radians(tilt_deg) * np.sqrt((k + 0.5) / n)
        tilt = np.array([np.cos(phi), np.sin(phi), 0.0]) * mag
        spin = rng.uniform(-0.3, 0.3)
        # Board facing the camera: its z axis points away from the camera (-z_cam).
        R = so3_exp(tilt) @ np.diag([1.0, -1.0, -1.0]) @ so3_exp(np.array([0, 0, spin]))
        z = rng.uniform(*distance)
        # Spread the board over the whole view (corners included), or the lens distortion
        # is extrapolated where no corner was seen: a 3 x 3 cycle of offsets.
        gx, gy = (k % 3) - 1, ((k // 3) % 3) - 1
        c = np.array(
            [
                gx * spread[0] * z + rng.uniform(-0.002, 0.002),
                gy * spread[1] * z + rng.uniform(-0.002, 0.002),
                z,
            ]
        )
        out[k, :3, :3] = R
        out[k, :3, 3] = c - R @ centre
        out[k, 3, 3] = 1.0
    return out


@dataclass
class CalibrationSession:
    """Images of one simulated calibration and the poses they were rendered at."""

    chessboard_images: list[np.ndarray]
    chessboard_poses: Float
    plane_poses: Float  # (K, 4, 4) target poses of the light-plane calibration
    plane_board_images: list[np.ndarray]  # one chessboard image per target pose
    plane_stripe_images: list[np.ndarray]  # per pose: (M, H, W) stripe images


def simulate_calibration(
    sensor: Sensor,
    rng: np.random.Generator,
    *,
    n_views: int = 15,
    n_plane_poses: int = 4,
    target: ChessboardTarget | None = None,
    renderer: StripeRenderer | None = None,
    plane_indices: np.ndarray | None = None,
) -> CalibrationSession:
    """Chessboard views for the camera, then the target at a few poses for the planes.

    ``plane_indices`` renders the stripes of those planes only (the others are left out of
    ``plane_stripe_images[k]`` entirely: ``plane_stripe_images[k][j]`` is plane
    ``plane_indices[j]``).
    """
    tgt = target or ChessboardTarget()
    views = board_views(rng, n_views, tgt)
    cb = [render_chessboard(sensor.camera, T, rng, tgt) for T in views]
    # Plane target: roughly facing the camera, at depths spread over the working range.
    ppos = board_views(rng, n_plane_poses, tgt, tilt_deg=15.0, spread=(0.01, 0.01))
    depths = np.linspace(0.112, 0.138, n_plane_poses)
    ppos[:, 2, 3] += depths - ppos[:, 2, 3]
    ren = renderer or StripeRenderer(sensor.camera, sensor.planes)
    board_imgs, stripes = [], []
    for T in ppos:
        board_imgs.append(render_chessboard(sensor.camera, T, rng, tgt))
        scene = Scene(planes=(PlaneSurface(T[:3, 3].copy(), T[:3, 2].copy()),))
        stripes.append(ren.render_scan(scene, rng, plane_indices))
    return CalibrationSession(cb, views, ppos, board_imgs, stripes)


def sphere_scene(center: Float, radius: float, albedo: float = 1.0) -> Scene:
    """A single ceramic sphere in the camera frame."""
    return Scene(
        spheres=(SphereSurface(np.asarray(center, float), float(radius), albedo),)
    )
