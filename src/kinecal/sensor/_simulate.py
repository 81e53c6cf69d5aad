"""Simulated sensor sessions: calibration views, plane-target poses and sphere scans.

Images are rendered when they are read (:class:`RenderedImages`), each from its own
random stream: a session of 15 chessboard views and 5 x 120 stripe images holds no image
until asked, any number of threads can render it at once, and every image is the same
whatever the order or the threads that read it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import overload

import numpy as np

from kinecal.geometry import so3_exp
from kinecal.sensor._board import ChessboardTarget, render_chessboard
from kinecal.sensor._camera import Camera
from kinecal.sensor._render import (
    PlaneSurface,
    PreparedScene,
    Scene,
    SphereSurface,
    StripeRenderer,
)
from kinecal.sensor._sensor import Sensor
from kinecal.typing import Float

__all__ = [
    "CalibrationSession",
    "RenderedImages",
    "board_views",
    "simulate_calibration",
    "sphere_scene",
]


def _fit_in_view(
    T: Float, camera: Camera, target: ChessboardTarget, border: float
) -> Float:
    """Shift a board pose (4, 4) across the view until its pattern, with ``border``
    squares of the white panel around it, lies inside the image (a few Newton steps on
    the overflow in pixels; a board too large for the view stays centred)."""
    T = T.copy()
    W, H = camera.width, camera.height
    out = target.outline(border)
    for _ in range(10):
        uv = camera.project(out @ T[:3, :3].T + T[:3, 3])
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        limit_hi = np.array([W - 1.0, H - 1.0])
        over = np.maximum(0.0 - lo, 0.0) - np.maximum(hi - limit_hi, 0.0)
        if np.all(over == 0.0):
            break
        if np.any((hi - lo) > limit_hi):
            break
        T[:2, 3] += over * T[2, 3] / np.array([camera.fx, camera.fy]) * 1.05
    return T


def board_views(
    rng: np.random.Generator,
    n: int,
    target: ChessboardTarget | None = None,
    *,
    distance: tuple[float, float] = (0.115, 0.135),
    tilt_deg: float = 30.0,
    spread: tuple[float, float] = (0.075, 0.06),
    camera: Camera | None = None,
    border_squares: float = 0.5,
) -> Float:
    """Poses (n, 4, 4) of the chessboard in the camera frame.

    Tilts are spread in direction (a golden-angle spiral) so that Zhang's method sees the
    board from many sides, the condition for a well-determined focal length; the board
    centre moves over a 3 x 3 grid of directions ``spread`` (x, y per metre of depth), so
    that the corners of the views reach the corners of the image. With ``camera``, each
    board is then moved towards the centre until its pattern and ``border_squares`` of
    white around it are in view (as one places a board to be detected whole).
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
        if camera is not None:
            out[k] = _fit_in_view(out[k], camera, tgt, border_squares)
    return out


class RenderedImages(Sequence[np.ndarray]):
    """A sequence of images rendered on access: item ``j`` is ``render(j, rng_j)`` with
    ``rng_j`` seeded by ``(*key, j)``, so an image is the same whenever, in whatever
    thread, it is read. Nothing is kept between reads except what ``setup`` returns
    (computed once, on first access, under a lock; :meth:`release` drops it)."""

    def __init__(
        self,
        n: int,
        render: Callable[[object, int, np.random.Generator], np.ndarray],
        key: tuple[int, ...],
        setup: Callable[[], object] | None = None,
    ) -> None:
        self._n, self._render, self._key, self._setup = n, render, key, setup
        self._state: object = None
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return self._n

    @overload
    def __getitem__(self, j: int) -> np.ndarray: ...

    @overload
    def __getitem__(self, j: slice) -> list[np.ndarray]: ...

    def __getitem__(self, j: int | slice) -> np.ndarray | list[np.ndarray]:
        if isinstance(j, slice):
            return [self[i] for i in range(*j.indices(self._n))]
        if not -self._n <= j < self._n:
            raise IndexError(f"image {j} of {self._n}")
        j = j % self._n
        state = None
        if self._setup is not None:
            with self._lock:
                if self._state is None:
                    self._state = self._setup()
                state = self._state
        return self._render(state, j, np.random.default_rng([*self._key, j]))

    def release(self) -> None:
        """Drop what ``setup`` computed (it is computed again if an image is read)."""
        with self._lock:
            self._state = None


@dataclass
class CalibrationSession:
    """Images of one simulated calibration and the poses they were rendered at.

    The image sequences render on access (:class:`RenderedImages`).
    """

    chessboard_images: Sequence[np.ndarray]
    chessboard_poses: Float
    plane_poses: Float  # (K, 4, 4) target poses of the light-plane calibration
    plane_board_images: Sequence[np.ndarray]  # one chessboard image per target pose
    plane_stripe_images: list[Sequence[np.ndarray]]  # per pose: M stripe images
    plane_indices: np.ndarray  # (M,) light plane of each stripe image


def _stripes(
    ren: StripeRenderer, scene: Scene, idx: np.ndarray, key: tuple[int, ...]
) -> RenderedImages:
    def render(prep: object, j: int, rng: np.random.Generator) -> np.ndarray:
        assert isinstance(prep, PreparedScene)
        return ren.render(prep, int(idx[j]), rng)

    return RenderedImages(len(idx), render, key, lambda: ren.prepare(scene))


def simulate_calibration(
    sensor: Sensor,
    rng: np.random.Generator,
    *,
    n_views: int = 25,
    n_plane_poses: int = 5,
    tilt_deg: float = 40.0,
    target: ChessboardTarget | None = None,
    renderer: StripeRenderer | None = None,
    plane_indices: np.ndarray | None = None,
) -> CalibrationSession:
    """Chessboard views for the camera, then the target at a few poses for the planes.

    The camera's views (``tilt_deg`` the largest tilt) spread over the image; 25 views
    tilted up to 40 deg determine the focal length to about 0.4 px, the principal point
    to 0.5 px (15 views at 30 deg: 0.7 px, 0.8 px), which set how far the sensor's
    frame is from the truth (0.4 px: 16 um at 140 mm).

    ``plane_indices`` renders the stripes of those planes only (the others are left out of
    ``plane_stripe_images[k]`` entirely: ``plane_stripe_images[k][j]`` is plane
    ``plane_indices[j]``). The poses are drawn from ``rng`` now; the images are rendered
    when read, from streams seeded by one further draw of ``rng``.
    """
    tgt = target or ChessboardTarget()
    cam = sensor.camera
    views = board_views(rng, n_views, tgt, camera=cam, tilt_deg=tilt_deg)
    # Plane target: roughly facing the camera, at depths spread over the working range.
    ppos = board_views(rng, n_plane_poses, tgt, tilt_deg=15.0, spread=(0.01, 0.01))
    ppos[:, 2, 3] = np.linspace(0.112, 0.138, n_plane_poses)
    for k in range(n_plane_poses):
        ppos[k] = _fit_in_view(ppos[k], cam, tgt, 0.5)
    base = int(rng.integers(0, 2**62))
    idx = (
        np.arange(len(sensor.planes))
        if plane_indices is None
        else np.asarray(plane_indices, np.intp)
    )
    ren = renderer or StripeRenderer(cam, sensor.planes)

    def board(poses: Float) -> Callable[[object, int, np.random.Generator], np.ndarray]:
        return lambda _, j, g: render_chessboard(cam, poses[j], g, tgt)

    stripes = [
        _stripes(
            ren,
            Scene(planes=(PlaneSurface(T[:3, 3].copy(), T[:3, 2].copy()),)),
            idx,
            (base, 2, k),
        )
        for k, T in enumerate(ppos)
    ]
    return CalibrationSession(
        RenderedImages(n_views, board(views), (base, 0)),
        views,
        ppos,
        RenderedImages(n_plane_poses, board(ppos), (base, 1)),
        list(stripes),
        idx,
    )


def sphere_scene(center: Float, radius: float, albedo: float = 1.0) -> Scene:
    """A single ceramic sphere in the camera frame."""
    return Scene(
        spheres=(SphereSurface(np.asarray(center, float), float(radius), albedo),)
    )
