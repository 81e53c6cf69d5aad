"""The sensor calibrated as a whole: camera, board poses and light planes together.

The paper calibrates the camera (Zhang's method) and then fits every light plane to its
stripes on the target, with the target poses taken as exact. Here one bundle adjustment
(:func:`~kinecal.sensor._bundle.bundle_adjust`) estimates the intrinsics, the pose of
every board view (the camera's views and the target's poses for the planes) and every
light plane seen at two or more target poses, from the corners and the stripe centres
together, each weighted by its own estimated noise. Planes seen at fewer poses are then
placed about the mirror axis of the others (``model="auto"``), or all planes are
(``"rotary"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kinecal.errors import DataError
from kinecal.sensor._board import ChessboardTarget
from kinecal.sensor._bundle import BundleResult, Stripes, bundle_adjust
from kinecal.sensor._calibrate import (
    CameraCalibration,
    Detection,
    _camera_result,
    check_options,
    common_size,
    detect_all,
    free_k3_if_determined,
    pnp_poses,
    reject_views,
    zhang_start,
)
from kinecal.sensor._camera import INTRINSICS, Camera
from kinecal.sensor._planes import LightPlanes, axis_fit, fit_plane
from kinecal.sensor._sensor import Sensor
from kinecal.sensor._stripes import extract_stripes_all
from kinecal.typing import Float

__all__ = [
    "PlaneCalibration",
    "SensorCalibration",
    "calibrate_planes",
    "calibrate_sensor",
]

# Stripe centres further than this many standard deviations from their plane are left
# out (mis-extracted rows: glare, the target's edge), and the adjustment repeated.
_STRIPE_OUTLIER_K = 5.0


@dataclass(frozen=True)
class PlaneCalibration:
    planes: LightPlanes
    rms_mm: Float  # (M,) RMS distance of each plane's points from it (NaN: unseen)
    n_points: np.ndarray  # (M,)
    status: list[
        str
    ]  # per plane: "free", "axis" (fitted about the mirror axis), "unseen"
    std_mm: Float | None = (
        None  # (M,) std of each adjusted plane at its points (NaN: not)
    )

    @property
    def mean_rms_mm(self) -> float:
        """The paper's plane-fit error: mean over the planes of their RMS [mm]."""
        return float(np.nanmean(self.rms_mm))


@dataclass(frozen=True)
class SensorCalibration:
    """Result of :func:`calibrate_sensor`."""

    camera: CameraCalibration
    planes: PlaneCalibration
    plane_poses: list[int]  # target poses used (their board was found)
    sigma_stripe_px: float  # a-posteriori std of a stripe centre along its row
    stripe_outliers: int  # stripe centres left out
    bundle: BundleResult

    @property
    def sensor(self) -> Sensor:
        return Sensor(self.camera.camera, self.planes.planes)


def _on_target(camera: Camera, T: Float, uv: Float) -> Float:
    """Where the rays of pixels ``uv`` (K, 2) meet the board plane of pose ``T``."""
    n = T[:3, 2]
    rays = camera.rays(uv)
    return rays * ((n @ T[:3, 3]) / (rays @ n))[:, None]


def _plane_images(
    stripe_images: Sequence[Sequence[np.ndarray | None]],
    plane_indices: Sequence[int] | None,
    n_planes: int | None,
) -> tuple[np.ndarray, int]:
    M_img = len(stripe_images[0]) if len(stripe_images) else 0
    for k, imgs in enumerate(stripe_images):
        if len(imgs) != M_img:
            raise DataError(
                f"target pose {k} has {len(imgs)} stripe images, expected {M_img}"
            )
    idx = np.arange(M_img) if plane_indices is None else np.asarray(plane_indices)
    if idx.shape != (M_img,):
        raise DataError(f"{M_img} stripe images per pose but {idx.size} plane indices")
    M = int(n_planes) if n_planes is not None else int(idx.max(initial=-1)) + 1
    if idx.size and (idx.min() < 0 or idx.max() >= M):
        raise DataError(f"plane indices must lie in 0..{M - 1}")
    return idx, M


def _extract(
    stripe_images: Sequence[Sequence[np.ndarray | None]],
    poses: list[int],
    first_view: int,
    idx: np.ndarray,
    jobs: int,
) -> Stripes:
    """Stripe centres of the target poses ``poses`` (their views from ``first_view``)."""
    uv, view, plane = [np.zeros((0, 2))], [np.zeros(0, np.intp)], [np.zeros(0, np.intp)]
    for j, k in enumerate(poses):
        for st, i in zip(extract_stripes_all(stripe_images[k], jobs=jobs), idx):
            if st is None or st.shape[0] == 0:
                continue
            uv.append(st[:, :2])
            view.append(np.full(st.shape[0], first_view + j))
            plane.append(np.full(st.shape[0], int(i)))
    return Stripes(np.concatenate(uv), np.concatenate(view), np.concatenate(plane))


def _planes_result(
    camera: Camera,
    T: Float,
    stripes: Stripes,
    n: Float,
    b: Float,
    adjusted: np.ndarray,
    std_m: Float,
    model: str,
    source: Float | None,
) -> PlaneCalibration:
    """Planes seen at too few poses placed about the mirror axis (``model``), the
    normals oriented (positive x, for a source at +x), the RMS of each plane's points."""
    M = n.shape[0]
    clouds = []
    for i in range(M):
        sel = stripes.plane == i
        pts = [
            _on_target(camera, T[v], stripes.uv[sel & (stripes.view == v)])
            for v in np.unique(stripes.view[sel])
        ]
        clouds.append(np.concatenate(pts) if pts else np.zeros((0, 3)))
    n, b = n.copy(), b.copy()
    flip = n[:, 0] < 0
    n[flip] *= -1
    b[flip] *= -1
    status = np.where(adjusted, "free", "unseen")
    if model == "rotary" or not adjusted.all():
        n, b, status = axis_fit(n, b, clouds, adjusted, model == "rotary")
    rms = np.array(
        [
            np.sqrt(np.mean((c @ nn + bb) ** 2)) * 1e3 if c.shape[0] else np.nan
            for c, nn, bb in zip(clouds, n, b)
        ]
    )
    counts = np.array([c.shape[0] for c in clouds], np.intp)
    return PlaneCalibration(
        LightPlanes(n, b, source), rms, counts, [str(s) for s in status], std_m * 1e3
    )


def calibrate_sensor(
    board_images: Sequence[np.ndarray],
    target: ChessboardTarget,
    plane_board_images: Sequence[np.ndarray | None],
    stripe_images: Sequence[Sequence[np.ndarray | None]],
    *,
    plane_indices: Sequence[int] | None = None,
    n_planes: int | None = None,
    camera: Camera | None = None,
    model: str = "auto",
    min_poses: int = 2,
    min_views: int = 5,
    k3: str = "auto",
    detector: str = "auto",
    source: Float | None = None,
    stripe_points: int = 64,
    jobs: int = 0,
) -> SensorCalibration:
    """Camera and light planes in one bundle adjustment.

    ``board_images``: the camera's chessboard views; ``plane_board_images[k]``: the board
    at target pose ``k`` (backlight on); ``stripe_images[k][j]``: the stripe of light
    plane ``plane_indices[j]`` (default ``j``) on the target at pose ``k`` (backlight
    off; None: not imaged). With ``camera`` the intrinsics are held at its values (and
    ``board_images`` may be empty). ``model``: ``"free"`` every plane on its own (each
    must be seen at ``min_poses`` poses), ``"rotary"`` every plane about the common
    mirror axis, ``"auto"`` on its own where seen at ``min_poses`` poses and about the
    axis otherwise. ``k3`` as in :func:`~kinecal.sensor.calibrate_camera`. The
    adjustment uses ``stripe_points`` centres of each stripe (evenly spaced; the planes'
    precision is set by the target poses, not by the number of centres); all of them
    serve the outlier test and the planes' RMS. Images are read and searched on ``jobs``
    threads (0: one per CPU).
    """
    if model not in ("auto", "free", "rotary"):
        raise DataError(f"model must be auto, free or rotary, got {model!r}")
    check_options(k3, detector)
    if len(plane_board_images) != len(stripe_images):
        raise DataError(
            f"{len(plane_board_images)} target board images but {len(stripe_images)} "
            "sets of stripe images"
        )
    idx, M = _plane_images(stripe_images, plane_indices, n_planes)
    found, found_p, used, poses = _detect(
        board_images,
        plane_board_images,
        target,
        camera,
        detector,
        jobs,
        min_views,
        min_poses,
    )
    both = [found[k] for k in used] + [found_p[k] for k in poses]
    size = common_size(both, "calibrate_sensor")
    corners = np.stack([d.corners for d in both if d.corners is not None])
    if camera is None:
        cam0, T0 = zhang_start(corners, target, size)
    else:
        cam0, T0 = camera, pnp_poses(corners, camera, target)
    stripes = _extract(stripe_images, poses, len(used), idx, jobs)
    n0, b0, adjust = _start_planes(cam0, T0, stripes, M, min_poses, model)
    on_adjusted = adjust[stripes.plane]
    bundle = _Bundle(
        corners,
        target.object_points(),
        stripes,
        (n0, b0),
        adjust,
        on_adjusted.copy(),
        _thin(stripes, stripe_points),
    )
    fixed = INTRINSICS if camera is not None else ("k3",)
    cam = cam0 if camera is not None else cam0.with_(k3=0.0)
    rejected: list[int] = []
    res, n_cam = _rounds(bundle, cam, T0, fixed, used, rejected, min_views, on_adjusted)
    test: dict[str, float] = {}
    if camera is None:
        res, test = free_k3_if_determined(bundle.run, res, k3)
    cc = _camera_result(
        res, used, rejected, [found[k].detector for k in used], test, n_views=n_cam
    )
    stripes, keep = bundle.stripes, bundle.keep
    pc = _planes_result(
        res.camera,
        res.T_cam_board,
        Stripes(stripes.uv[keep], stripes.view[keep], stripes.plane[keep]),
        res.n,
        res.b,
        adjust,
        res.plane_std_m,
        model,
        source,
    )
    outliers = int((on_adjusted & ~keep).sum())
    return SensorCalibration(cc, pc, poses, res.sigma_stripe_px, outliers, res)


def _detect(
    board_images: Sequence[np.ndarray],
    plane_board_images: Sequence[np.ndarray | None],
    target: ChessboardTarget,
    camera: Camera | None,
    detector: str,
    jobs: int,
    min_views: int,
    min_poses: int,
) -> tuple[list[Detection], list[Detection], list[int], list[int]]:
    """The board found in the camera's views and at the target poses: the detections
    in either, and the camera views and the target poses where it was found."""
    found = detect_all(board_images, target, detector, jobs)
    used = [k for k, d in enumerate(found) if d.corners is not None]
    if camera is None and len(used) < min_views:
        raise DataError(
            f"the {target.cols}x{target.rows} chessboard was found in {len(used)} of "
            f"{len(board_images)} camera views; at least {min_views} are needed"
        )
    found_p = detect_all(plane_board_images, target, detector, jobs)
    poses = [k for k, d in enumerate(found_p) if d.corners is not None]
    if len(poses) < min_poses:
        raise DataError(
            f"the board was found at {len(poses)} of {len(plane_board_images)} target "
            f"poses; at least {min_poses} are needed for the light planes"
        )
    return found, found_p, used, poses


def _start_planes(
    cam0: Camera, T0: Float, stripes: Stripes, M: int, min_poses: int, model: str
) -> tuple[Float, Float, np.ndarray]:
    """Starting planes ``(n, b)``, fitted to their stripes on the starting target
    planes, and which planes the adjustment fits (seen at ``min_poses`` poses)."""
    n0, b0 = np.zeros((M, 3)), np.zeros(M)
    n0[:, 0] = 1.0
    adjust = np.zeros(M, bool)
    for i in range(M):
        sel = stripes.plane == i
        views = np.unique(stripes.view[sel])
        if views.size < min_poses or views.size < 2:
            continue
        pts = np.concatenate(
            [
                _on_target(cam0, T0[v], stripes.uv[sel & (stripes.view == v)])
                for v in views
            ]
        )
        try:
            n0[i], b0[i], _ = fit_plane(pts)
        except DataError:
            continue
        adjust[i] = True
    if model == "free" and not adjust.all():
        bad = int(np.flatnonzero(~adjust)[0])
        raise DataError(
            f"light plane {bad} was seen at fewer than {min_poses} target poses "
            "(or not at all); use model 'auto' or 'rotary'"
        )
    if adjust.sum() < 2:
        raise DataError(
            f"only {int(adjust.sum())} light planes were seen at {min_poses} or more "
            "target poses; move the target through the working range"
        )
    return n0, b0, adjust


@dataclass
class _Bundle:
    """The adjustment's data, as the rejection rounds change them: the board corners
    (camera views, then target poses), the stripe centres, the planes to start from,
    which planes are adjusted, the centres kept and those the adjustment uses."""

    corners: Float
    obj: Float
    stripes: Stripes
    planes: tuple[Float, Float]
    adjust: np.ndarray
    keep: np.ndarray
    thin: np.ndarray

    def run(self, c: Camera, Ts: Float, fx: tuple[str, ...]) -> BundleResult:
        """The bundle adjustment from camera ``c`` and board poses ``Ts``."""
        use = self.keep & self.thin
        st = self.stripes
        return bundle_adjust(
            c,
            Ts,
            self.corners,
            self.obj,
            stripes=Stripes(st.uv[use], st.view[use], st.plane[use]),
            planes=self.planes,
            adjust_planes=self.adjust,
            fixed=fx,
        )


def _rounds(
    bundle: _Bundle,
    cam: Camera,
    T: Float,
    fixed: tuple[str, ...],
    used: list[int],
    rejected: list[int],
    min_views: int,
    on_adjusted: np.ndarray,
) -> tuple[BundleResult, int]:
    """Adjustments (k3 held at 0) while camera views and stripe centres that do not fit
    are found: a rejected view moves from ``used`` to ``rejected``, the stripe centres
    kept are ``bundle.keep``. The last adjustment and the number of camera views."""
    n_cam = len(used)
    rounds = 0
    for _ in range(len(used) + 4):
        res = bundle.run(cam, T, fixed)
        cam, T, bundle.planes = res.camera, res.T_cam_board, (res.n, res.b)
        per_view = np.sqrt(np.mean(res.corner_residuals_px[:n_cam] ** 2, axis=(1, 2)))
        drop = reject_views(per_view, min_views) if n_cam else None
        if drop is not None:  # a camera view with mis-detected corners
            rejected.append(used.pop(drop))
            n_cam -= 1
            sel = np.arange(bundle.corners.shape[0]) != drop
            bundle.corners, T = bundle.corners[sel], T[sel]
            st = bundle.stripes
            bundle.stripes = Stripes(st.uv, st.view - 1, st.plane)
            continue
        # Stripe centres far from their plane (the left-out ones judged again too).
        st = bundle.stripes
        s = _distances(res.camera, T, res.n, res.b, st)
        w = _row_scale(res.camera, T, res.n, res.b, st)
        new = on_adjusted & (np.abs(s / w) <= _STRIPE_OUTLIER_K * res.sigma_stripe_px)
        rounds += 1
        changed = int(np.sum(new != bundle.keep))
        bundle.keep = new
        if changed <= 1e-3 * new.size or rounds >= 3:
            break
    return res, n_cam


def _thin(sp: Stripes, per_stripe: int) -> np.ndarray:
    """Every k-th centre of each stripe (view and plane), k chosen so that at most
    ``per_stripe`` remain: a mask (S,)."""
    key = sp.view.astype(np.int64) * (int(sp.plane.max(initial=0)) + 1) + sp.plane
    order = np.argsort(key, kind="stable")
    k = key[order]
    start = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    size = np.diff(np.r_[start, k.size])
    rank = np.arange(k.size) - np.repeat(start, size)
    step = np.repeat(-(-size // max(per_stripe, 1)), size)
    out = np.zeros(k.size, bool)
    out[order] = rank % step == 0
    return out


def _distances(camera: Camera, T: Float, n: Float, b: Float, sp: Stripes) -> Float:
    """Signed distances (S,) [m] of the stripe points on their target from their plane."""
    xy = camera.normalised(sp.uv)
    r = np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)
    m = T[sp.view, :3, 2]
    X = (
        r
        * (np.einsum("ij,ij->i", m, T[sp.view, :3, 3]) / np.einsum("ij,ij->i", m, r))[
            :, None
        ]
    )
    return np.einsum("ij,ij->i", X, n[sp.plane]) + b[sp.plane]


def _row_scale(camera: Camera, T: Float, n: Float, b: Float, sp: Stripes) -> Float:
    """``|ds/du|`` (S,) [m/px]: how far a stripe point moves from its plane per pixel
    along the row (central difference over one pixel)."""
    d = np.array([[0.5, 0.0]])
    hi = _distances(camera, T, n, b, Stripes(sp.uv + d, sp.view, sp.plane))
    lo = _distances(camera, T, n, b, Stripes(sp.uv - d, sp.view, sp.plane))
    return np.abs(hi - lo)


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
    """Fit every light plane to its stripes on the target at known poses (the paper's
    separate plane calibration: camera and poses taken as exact).

    ``target_poses[k]`` is the target's pose (4, 4) in the camera frame at pose ``k`` and
    ``stripe_images[k][i]`` the image of light plane ``i`` at that pose. ``model`` as in
    :func:`calibrate_sensor`. :func:`calibrate_sensor` adjusts the camera and the poses
    with the planes; this function does not.
    """
    if model not in ("auto", "free", "rotary"):
        raise DataError(
            f"calibrate_planes: model must be auto, free or rotary, got {model!r}"
        )
    if len(target_poses) != len(stripe_images):
        raise DataError(
            f"calibrate_planes: {len(target_poses)} target poses, "
            f"{len(stripe_images)} image sets"
        )
    if len(target_poses) < min_poses:
        raise DataError(f"calibrate_planes: need at least {min_poses} target poses")
    idx, M = _plane_images(stripe_images, None, None)
    T = np.stack([np.asarray(t, float) for t in target_poses])
    stripes = _extract(stripe_images, list(range(len(T))), 0, idx, jobs)
    n, b = np.zeros((M, 3)), np.zeros(M)
    n[:, 0] = 1.0
    free = np.zeros(M, bool)
    for i in range(M):
        sel = stripes.plane == i
        views = np.unique(stripes.view[sel])
        if views.size >= max(min_poses, 2):
            pts = np.concatenate(
                [
                    _on_target(camera, T[v], stripes.uv[sel & (stripes.view == v)])
                    for v in views
                ]
            )
            n[i], b[i], _ = fit_plane(pts)
            free[i] = True
    if free.sum() < 2:
        raise DataError(
            f"calibrate_planes: only {int(free.sum())} light planes were seen at "
            f"{min_poses} or more target poses; move the target through the working range"
        )
    if model == "free" and not free.all():
        bad = int(np.flatnonzero(~free)[0])
        raise DataError(
            f"calibrate_planes: light plane {bad} was seen at fewer than {min_poses} "
            "target poses; at least that many are needed (or use model='auto')"
        )
    return _planes_result(
        camera, T, stripes, n, b, free, np.full(M, np.nan), model, source
    )
