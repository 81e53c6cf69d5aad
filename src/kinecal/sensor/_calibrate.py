"""Sensor calibration: camera intrinsics (Zhang, via OpenCV) and the light planes.

Camera: chessboard corners (``findChessboardCorners`` + ``cornerSubPix``) from several
views, then ``calibrateCameraExtended`` (k1, k2, k3, p1, p2), which also returns the
standard deviations of the intrinsics and the per-view re-projection errors.

Light planes: the planar target is seen at several poses; at each pose the chessboard
image gives the target plane in the camera frame (``solvePnP`` with the calibrated
camera), and the stripe images of every light plane, taken with the pattern's backlight
off, give stripe pixels whose rays meet the target plane in 3-D points. Each light plane
is the least-squares plane through its points from all poses.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinecal._parallel import thread_map
from kinecal.errors import DataError
from kinecal.sensor._camera import Camera
from kinecal.sensor._cv import require_cv2
from kinecal.sensor._planes import LightPlanes, fit_plane
from kinecal.sensor._render import ChessboardTarget
from kinecal.sensor._stripes import extract_stripes_all
from kinecal.typing import Float

__all__ = [
    "CameraCalibration",
    "PlaneCalibration",
    "board_pose",
    "calibrate_camera",
    "calibrate_planes",
    "find_corners",
]


def _cv2() -> Any:
    return require_cv2("the sensor calibration")


@dataclass(frozen=True)
class CameraCalibration:
    camera: Camera
    rms_px: float  # overall re-projection error
    per_view_px: Float
    std: dict[str, float]  # standard deviation of each intrinsic
    T_cam_board: Float  # (V, 4, 4) board poses of the views used
    used: list[int]  # indices of the images used
    rejected: list[
        int
    ]  # board found but corners inconsistent with the others (dropped)


@dataclass(frozen=True)
class PlaneCalibration:
    planes: LightPlanes
    rms_mm: Float  # (M,) RMS distance of each plane's points from it (NaN: unseen)
    n_points: np.ndarray  # (M,)
    status: list[
        str
    ]  # per plane: "free", "axis" (fitted about the mirror axis), "unseen"

    @property
    def mean_rms_mm(self) -> float:
        return float(np.nanmean(self.rms_mm))


def find_corners(image: np.ndarray, target: ChessboardTarget) -> Float | None:
    """Sub-pixel inner corners (rows*cols, 2) of the chessboard, or ``None``."""
    cv2 = _cv2()
    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(
        img, (target.cols, target.rows), flags=flags
    )
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    corners = cv2.cornerSubPix(img, corners, (7, 7), (-1, -1), crit)
    c = corners.reshape(target.rows, target.cols, 2).astype(float)
    # OpenCV may list the corners of a board mirrored with respect to the object points
    # (which corner comes first depends on the pattern's parity). Object x along a row and
    # y down the rows must appear right-handed in the image (u right, v down), as a board
    # seen from its printed face does; otherwise reverse the rows.
    d_col = c[0, -1] - c[0, 0]
    d_row = c[-1, 0] - c[0, 0]
    if d_col[0] * d_row[1] - d_col[1] * d_row[0] < 0:
        c = c[:, ::-1]
    return c.reshape(-1, 2)


def _pose(rvec: Float, tvec: Float) -> Float:
    cv2 = _cv2()
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(np.asarray(rvec, float).reshape(3, 1))[0]
    T[:3, 3] = np.asarray(tvec, float).ravel()
    return T


def calibrate_camera(
    images: Sequence[np.ndarray],
    target: ChessboardTarget,
    *,
    min_views: int = 5,
    jobs: int = 0,
) -> CameraCalibration:
    """Zhang's method on chessboard images (lengths of the result in metres); the boards
    are searched on ``jobs`` threads (0: one per CPU)."""
    cv2 = _cv2()
    if not images:
        raise DataError("calibrate_camera: no images")
    H, W = np.asarray(images[0]).shape[:2]
    obj = target.object_points().astype(np.float32)
    obj_pts, img_pts, used = [], [], []
    for k, img in enumerate(images):
        if np.asarray(img).shape[:2] != (H, W):
            raise DataError(
                f"calibrate_camera: image {k} is {img.shape[:2]}, expected {(H, W)}"
            )
    # OpenCV's board search releases the interpreter: one thread per CPU. It takes a few
    # ms where it finds the board and seconds where it does not (a board cut by the image
    # border: 2-3 s per 1280 x 1024 view here), so those views dominate.
    found = thread_map(lambda img: find_corners(img, target), images, jobs)
    for k, c in enumerate(found):
        if c is not None:
            obj_pts.append(obj)
            img_pts.append(c.astype(np.float32))
            used.append(k)
    if len(used) < min_views:
        raise DataError(
            f"calibrate_camera: the {target.cols}x{target.rows} chessboard was found in "
            f"{len(used)} of {len(images)} images; at least {min_views} are needed"
        )
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 200, 1e-12)
    rejected: list[int] = []
    while True:
        rms, K, dist, rvecs, tvecs, std_in, _std_ex, per_view = _one_cv_thread(
            cv2,
            lambda: cv2.calibrateCameraExtended(
                obj_pts, img_pts, (W, H), None, None, criteria=crit
            ),
        )
        # A view whose corners were mis-detected (board cut by the image border, glare)
        # stands out in its re-projection error: drop the worst such view and refit.
        pv = np.asarray(per_view, float).ravel()
        worst = int(np.argmax(pv))
        limit = max(4.0 * float(np.median(pv)), 0.3)
        if pv[worst] <= limit or len(used) - 1 < min_views:
            break
        rejected.append(used.pop(worst))
        obj_pts.pop(worst)
        img_pts.pop(worst)
    cam = Camera.from_opencv(K, dist, (W, H))
    s = np.asarray(std_in, float).ravel()
    names = ["fx", "fy", "u0", "v0", "k1", "k2", "p1", "p2", "k3"]
    return CameraCalibration(
        camera=cam,
        rms_px=float(rms),
        per_view_px=np.asarray(per_view, float).ravel(),
        std={n: float(v) for n, v in zip(names, s)},
        T_cam_board=np.stack([_pose(r, t) for r, t in zip(rvecs, tvecs)]),
        used=used,
        rejected=sorted(rejected),
    )


def _one_cv_thread(cv2: Any, run: Callable[[], Any]) -> Any:
    """``run()`` with OpenCV on one thread, so that the result is reproducible. On
    several threads calibrateCameraExtended sums in a varying order: on the 15 simulated
    views its fx changed in the 11th digit from run to run and its standard deviation of
    k3 between 0.024 and 0.037. OpenCV's thread count is global; it is restored after."""
    n = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        return run()
    finally:
        cv2.setNumThreads(n)


def board_pose(
    image: np.ndarray, camera: Camera, target: ChessboardTarget
) -> Float | None:
    """Pose (4, 4) of the chessboard in the camera frame, or ``None`` if not found."""
    cv2 = _cv2()
    c = find_corners(image, target)
    if c is None:
        return None
    ok, rvec, tvec = cv2.solvePnP(
        target.object_points(), c, camera.K, camera.dist, flags=cv2.SOLVEPNP_ITERATIVE
    )
    return _pose(rvec, tvec) if ok else None


def calibrate_planes(
    camera: Camera,
    target_poses: Sequence[Float],
    stripe_images: Sequence[Sequence[np.ndarray | None]],
    *,
    source: Float | None = None,
    min_poses: int = 2,
    model: str = "auto",
    jobs: int = 0,
) -> PlaneCalibration:
    """Fit every light plane to its stripes on the target at several poses.

    ``target_poses[k]`` is the target's pose (4, 4) in the camera frame at pose ``k`` and
    ``stripe_images[k][i]`` the image of light plane ``i`` at that pose. ``model``:
    ``"free"`` fits every plane on its own (each must be seen at ``min_poses`` poses),
    ``"rotary"`` fits every plane about the common mirror axis, ``"auto"`` fits planes on
    their own where they were seen at ``min_poses`` poses and about the axis otherwise.
    The stripes are extracted on ``jobs`` threads (0: one per CPU).
    """
    if model not in ("auto", "free", "rotary"):
        raise DataError(
            f"calibrate_planes: model must be auto, free or rotary, got {model!r}"
        )
    if len(target_poses) != len(stripe_images):
        raise DataError(
            f"calibrate_planes: {len(target_poses)} target poses, {len(stripe_images)} image sets"
        )
    if len(target_poses) < min_poses:
        raise DataError(f"calibrate_planes: need at least {min_poses} target poses")
    M = len(stripe_images[0])
    pts: list[list[Float]] = [[] for _ in range(M)]
    for k, (T, imgs) in enumerate(zip(target_poses, stripe_images)):
        if len(imgs) != M:
            raise DataError(
                f"calibrate_planes: pose {k} has {len(imgs)} images, expected {M}"
            )
        n = T[:3, 2]
        d0 = float(n @ T[:3, 3])
        for i, st in enumerate(extract_stripes_all(imgs, jobs=jobs)):
            if st is None:  # plane not imaged at this pose
                continue
            if st.shape[0] == 0:
                continue
            rays = camera.rays(st[:, :2])
            t = d0 / (rays @ n)
            pts[i].append(rays * t[:, None])
    clouds = [np.concatenate(p) if p else np.zeros((0, 3)) for p in pts]
    n_poses = np.array([len(p) for p in pts])
    free = n_poses >= min_poses
    if free.sum() < 2:
        raise DataError(
            f"calibrate_planes: only {int(free.sum())} light planes were seen at "
            f"{min_poses} or more target poses; move the target through the working range"
        )
    if model == "free" and not free.all():
        bad = int(np.flatnonzero(~free)[0])
        raise DataError(
            f"calibrate_planes: light plane {bad} was seen at {int(n_poses[bad])} target poses; "
            f"at least {min_poses} are needed (or use model='auto')"
        )
    normals = np.zeros((M, 3))
    b = np.zeros(M)
    for j in np.flatnonzero(free).tolist():
        normals[j], b[j], _ = fit_plane(clouds[j])
    # Keep the orientation convention of the design (normals with a positive x component
    # for a source at +x), so fitted and nominal planes compare directly.
    flip = normals[:, 0] < 0
    normals[flip] *= -1
    b[flip] *= -1
    status = np.where(free, "free", "")
    if model == "rotary" or not free.all():
        normals, b, status = _rotary(normals, b, clouds, free, model == "rotary")
    rms = np.array(
        [
            np.sqrt(np.mean((c @ nn + bb) ** 2)) * 1e3 if c.shape[0] else np.nan
            for c, nn, bb in zip(clouds, normals, b)
        ]
    )
    counts = np.array([c.shape[0] for c in clouds], np.intp)
    return PlaneCalibration(
        LightPlanes(normals, b, source), rms, counts, status.tolist()
    )


def _rotary(
    normals: Float, b: Float, clouds: list[Float], free: np.ndarray, all_planes: bool
) -> tuple[Float, Float, np.ndarray]:
    """Planes turning about one mirror axis, as the mechanism makes them.

    The axis is the line common to the freely fitted planes (direction: the null vector of
    their normals; point: least squares). A plane seen at one target pose only, or every
    plane when ``all_planes``, is then fitted with its normal perpendicular to the axis and
    the plane through it: one angle, in closed form. Planes never seen get the angle of a
    linear fit of angle against plane index (the mirror steps evenly).
    """
    N = normals[free]
    _, _, Vt = np.linalg.svd(N)
    a = Vt[2]
    S = np.linalg.lstsq(N, -b[free], rcond=None)[0]
    S = S - a * (a @ S)
    e1 = np.cross(a, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    psi = np.full(len(clouds), np.nan)
    status = np.where(free, "free", "unseen").astype(object)
    for i, c in enumerate(clouds):
        if c.shape[0] >= 2 and (all_planes or not free[i]):
            q = np.column_stack([(c - S) @ e1, (c - S) @ e2])
            _, V = np.linalg.eigh(q.T @ q)
            v = V[:, 0]
            psi[i] = np.arctan2(v[1], v[0])
            status[i] = "axis"
        elif free[i]:
            psi[i] = np.arctan2(normals[i] @ e2, normals[i] @ e1)
    # One branch for the angles (normals' sign is arbitrary).
    ref = psi[np.isfinite(psi)][0]
    psi = ref + (psi - ref + np.pi / 2) % np.pi - np.pi / 2
    seen = np.isfinite(psi)
    if not seen.all():
        idx = np.arange(len(clouds))
        coef = np.polyfit(idx[seen], psi[seen], 1)
        psi[~seen] = np.polyval(coef, idx[~seen])
    new_n = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2
    new_b = -(new_n @ S)
    flip = new_n[:, 0] < 0
    new_n[flip] *= -1
    new_b[flip] *= -1
    keep = free & ~np.asarray(all_planes, bool)
    new_n[keep] = normals[keep]
    new_b[keep] = b[keep]
    return new_n, new_b, status.astype(str)
