"""The sensor workflows of ``kinecal sensor``: a scan's point cloud from its stripe
images, a sphere fitted to a cloud, the camera from chessboard images, and the light
planes (with or without the camera) from stripes on a planar target."""

from __future__ import annotations

import math
import re
import threading
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kinecal.errors import DataError

if TYPE_CHECKING:  # the sensor's modules load when a workflow runs (OpenCV: slow)
    from kinecal.sensor import (
        Camera,
        CameraCalibration,
        ChessboardTarget,
        ScanCloud,
        Sensor,
        SensorCalibration,
        SphereFit,
    )

__all__ = [
    "CameraRun",
    "SensorRun",
    "calibrate_camera_images",
    "calibrate_sensor_images",
    "fit_cloud_sphere",
    "reconstruct_scan",
]

Progress = Callable[[str, str], None]


def _quiet(stage: str, detail: str) -> None:
    """No progress display."""


def reconstruct_scan(
    folder: str | Path,
    sensor: Sensor,
    *,
    method: str = "ridge",
    jobs: int = 0,
    source: str = "",
    progress: Progress | None = None,
) -> ScanCloud:
    """The point cloud of one scan, as ``kinecal sensor reconstruct`` writes it.

    ``folder`` holds ``plane_NNN.png`` (the stripe image of light plane NNN), all of the
    size of ``sensor``'s camera (``source``: the sensor file, for that message). Each
    image is read in the thread that extracts its stripes (``jobs`` threads, 0: one per
    CPU), and dropped after.

    Returns
    -------
    ScanCloud
        The points [m] in the camera frame, their pixels and planes.
    """
    from kinecal.io import image_files

    say = progress or _quiet
    files = image_files(folder, "plane_*.png")
    idx = np.array(plane_indices(files))
    say("images", f"{len(files)} stripe images")
    cam = sensor.camera
    if idx.max() >= len(sensor.planes):
        raise DataError(
            f"{files[int(idx.argmax())]}: light plane {int(idx.max())}; expected a "
            f"plane number 0..{len(sensor.planes) - 1}, the planes of the sensor "
            f"{source or 'file'}."
        )
    read = SameSize(read_scan_image, (cam.width, cam.height), source)
    cloud = sensor.scan(LazyImages(list(files), read), idx, jobs=jobs, method=method)
    if cloud.points.shape[0] == 0:  # an empty cloud is a result, but not a silent one
        import warnings

        warnings.warn(
            f"{folder}: no laser stripe found in any of its {len(files)} images (laser "
            "off, over- or under-exposed, the object out of view, or images of "
            "another sensor): the cloud is empty.",
            stacklevel=2,
        )
    return cloud


def fit_cloud_sphere(
    cloud: str | Path,
    *,
    radius_mm: float | None = None,
    outlier_k: float = 4.0,
    segment: bool = True,
) -> SphereFit:
    """The sphere ``kinecal sensor fit-sphere`` fits to the cloud file ``cloud``
    (``x_mm, y_mm, z_mm``): segmented from what surrounds it (``segment``), points
    beyond ``outlier_k`` robust std rejected (0: none), the radius known or fitted.

    Returns
    -------
    SphereFit
        Centre and radius [m] with their standard deviations.

    Raises
    ------
    DataError
        A cloud in metres, on a line or a plane, or too flat for its noise.
    """
    from kinecal.io import read_cloud
    from kinecal.sensor import fit_sphere

    P = read_cloud(cloud)
    if len(P) >= 5 and np.abs(P).max() * 1e3 < 5.0 and np.ptp(P, axis=0).max() > 0:
        raise DataError(
            f"{cloud}: columns x_mm, y_mm, z_mm: every value is below 5, which looks "
            "like metres; convert to millimetres."
        )
    try:
        return fit_sphere(
            P,
            radius=None if radius_mm is None else radius_mm * 1e-3,
            outlier_k=outlier_k if outlier_k > 0 else None,
            segment=segment,
        )
    except DataError as exc:
        raise DataError(f"{cloud}: {exc}") from None


def sphere_dict(f: SphereFit) -> dict[str, Any]:
    """The JSON object of ``kinecal sensor fit-sphere --json`` (mm, deg)."""
    return {
        "center_mm": (f.center * 1e3).tolist(),
        "radius_mm": f.radius * 1e3,
        "rms_mm": f.rms * 1e3,
        "n": f.n,
        "center_std_mm": (f.center_std * 1e3).tolist(),
        "radius_std_mm": f.radius_std * 1e3,
        "cap_half_angle_deg": float(np.degrees(f.cap_half_angle)),
        "n_points": int(f.inliers.size),
    }


def sphere_lines(f: SphereFit, fixed: bool = False) -> list[str]:
    """The lines ``kinecal sensor fit-sphere`` prints (``fixed``: the radius was
    given)."""
    d = sphere_dict(f)
    return [
        "centre  x {:.4f}  y {:.4f}  z {:.4f}  mm".format(*d["center_mm"]),
        "  std   x {:.5f}  y {:.5f}  z {:.5f}  mm".format(*d["center_std_mm"]),
        f"radius  {d['radius_mm']:.4f} mm"
        + (" (fixed)" if fixed else f"  std {d['radius_std_mm']:.5f} mm"),
        f"rms     {d['rms_mm']:.5f} mm over {f.n} of {f.inliers.size} points; cap "
        f"half-angle {d['cap_half_angle_deg']:.1f} deg",
    ]


def chessboard_target(board: str, square_mm: float) -> ChessboardTarget:
    """A chessboard of ``board`` (``COLSxROWS`` inner corners) and ``square_mm``.

    Raises
    ------
    ValueError
        (what is expected, the option: ``--board`` or ``--square-mm``): not COLSxROWS,
        fewer than 3 corners a way, two even or two odd counts (the board would look
        the same turned by 180 deg), a square that is not a finite number > 0.
    """
    from kinecal.sensor import ChessboardTarget

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", board)
    if not m:
        raise ValueError(f"expected COLSxROWS, e.g. 10x7; got {board!r}", "--board")
    cols, rows = int(m.group(1)), int(m.group(2))
    if min(cols, rows) < 3:
        raise ValueError(
            f"expected at least 3 inner corners each way; got {board!r}", "--board"
        )
    if cols % 2 == rows % 2:
        raise ValueError(
            f"expected one even and one odd count of inner corners (a board with two "
            f"even or two odd counts looks the same turned by 180 deg); got {board!r}",
            "--board",
        )
    if not (square_mm > 0 and math.isfinite(square_mm)):
        raise ValueError(
            f"expected a finite number > 0 [mm]; got {square_mm}", "--square-mm"
        )
    return ChessboardTarget(cols, rows, square_mm * 1e-3)


def camera_lines(cc: CameraCalibration) -> list[str]:
    """The intrinsics as the calibration commands print them: value and std, or why
    a term is fixed."""
    cam = cc.camera
    out = []
    for name in ("fx", "fy", "u0", "v0", "k1", "k2", "k3", "p1", "p2"):
        if name in cc.fixed:
            why = ""
            if name == "k3" and cc.k3_test:
                t = cc.k3_test
                why = (
                    "  (not determined: its std would move the image corner by "
                    f"{t.get('corner_px', float('nan')):.3f} px, over the "
                    f"{t.get('limit_px', float('nan')):.3f} px limit)"
                )
            out.append(f"  {name:3s} {getattr(cam, name):14.6f}  fixed{why}")
        else:
            out.append(f"  {name:3s} {getattr(cam, name):14.6f}  ± {cc.std[name]:.6f}")
    return out


@dataclass(frozen=True)
class CameraRun:
    """What :func:`calibrate_camera_images` found.

    Attributes
    ----------
    result : the camera calibration.
    files : the chessboard images, in order.
    skipped : those where no chessboard was found.
    rejected : those whose corners disagree with the other views.
    info : the sensor file's ``calibration`` section.
    """

    result: CameraCalibration
    files: tuple[Path, ...]
    skipped: tuple[Path, ...]
    rejected: tuple[Path, ...]
    info: dict[str, Any] = field(repr=False)

    def warning_lines(self) -> list[str]:
        """The images left out, and why."""
        return [
            f"warning: {f}: chessboard not found; image skipped" for f in self.skipped
        ] + [
            f"warning: {f}: corners inconsistent with the other views (re-projection "
            "error far above theirs); image left out"
            for f in self.rejected
        ]

    def summary_lines(self) -> list[str]:
        """The re-projection error and the intrinsics, as ``calibrate-camera`` prints
        them."""
        res = self.result
        return [
            f"re-projection RMS {res.rms_px:.4f} px over {len(res.used)} images "
            f"(corner std {res.sigma_px:.4f} px)",
            *camera_lines(res),
        ]


def calibrate_camera_images(
    folder: str | Path,
    target: ChessboardTarget,
    *,
    k3: str = "auto",
    detector: str = "auto",
    jobs: int = 0,
    board: str = "",
    square_mm: float | None = None,
    progress: Progress | None = None,
) -> CameraRun:
    """Camera intrinsics from the chessboard images in ``folder`` (``*.png``), as
    ``kinecal sensor calibrate-camera`` finds them (``board``: its COLSxROWS text, for
    messages; ``square_mm``: the square as given, for the file).

    Returns
    -------
    CameraRun
        The calibration and the images skipped or left out.

    Raises
    ------
    DataError
        Images of different sizes, too few boards found.
    """
    from kinecal.io import image_files, read_image
    from kinecal.sensor import calibrate_camera

    say = progress or _quiet
    files = image_files(folder)
    say("images", f"{len(files)} in {folder}")
    paths: list[Path | None] = [*files]
    imgs = LazyImages(paths, SameSize(read_image))
    try:
        res = calibrate_camera(imgs, target, jobs=jobs, k3=k3, detector=detector)
    except DataError as exc:  # the folder instead of the function's name
        text = str(exc)
        if not text.startswith("calibrate_camera: "):
            raise
        raise DataError(
            f"{folder}: {text.removeprefix('calibrate_camera: ')} (--board {board})"
        ) from None
    skipped = sorted(set(range(len(files))) - set(res.used) - set(res.rejected))
    return CameraRun(
        res,
        tuple(files),
        tuple(files[k] for k in skipped),
        tuple(files[k] for k in res.rejected),
        camera_info(res, target, square_mm),
    )


def camera_info(
    cc: CameraCalibration, tgt: ChessboardTarget, square_mm: float | None = None
) -> dict[str, Any]:
    """The ``calibration`` section of a camera file."""
    square = tgt.square * 1e3 if square_mm is None else square_mm
    return {
        "method": "bundle adjustment from Zhang's start (OpenCV calibrateCamera)",
        "images": len(cc.used),
        "rms_reprojection_px": cc.rms_px,
        "sigma_corner_px": cc.sigma_px,
        "std": cc.std,
        "fixed": list(cc.fixed),
        "k3_test": cc.k3_test,
        "detectors": dict(Counter(cc.detectors)),
        "board": {"cols": tgt.cols, "rows": tgt.rows, "square_mm": square},
    }


@dataclass(frozen=True)
class SensorRun:
    """What :func:`calibrate_sensor_images` found.

    Attributes
    ----------
    result : the calibration (camera if estimated, target poses, light planes).
    skipped : the target poses' board images where no chessboard was found.
    status : how many planes ended in each fit status.
    info : the sensor file's ``calibration`` section.
    """

    result: SensorCalibration
    skipped: tuple[Path, ...]
    status: dict[str, int]
    info: dict[str, Any] = field(repr=False)

    def summary_lines(self, camera_estimated: bool) -> list[str]:
        """What ``calibrate-planes`` prints: the camera (when ``camera_estimated``) and
        the light planes' fit."""
        res = self.result
        pc, n = res.planes, len(res.plane_poses)
        out = []
        if camera_estimated:
            cc = res.camera
            out.append(
                f"re-projection RMS {cc.rms_px:.4f} px over {len(cc.used)} views and "
                f"{n} target poses (corner std {cc.sigma_px:.4f} px)"
            )
            out += camera_lines(cc)
        out.append(
            f"{len(pc.planes)} light planes from {n} target poses: fit "
            f"RMS {pc.mean_rms_mm:.4f} mm (mean), {np.nanmax(pc.rms_mm):.4f} mm (max); "
            f"stripe std {res.sigma_stripe_px:.3f} px; "
            + ", ".join(f"{v} {k}" for k, v in self.status.items())
        )
        return out


def calibrate_sensor_images(
    folder: str | Path,
    target: ChessboardTarget,
    *,
    camera: Camera | None = None,
    chessboard: str | Path | None = None,
    n_planes: int | None = None,
    model: str = "auto",
    k3: str = "auto",
    detector: str = "auto",
    jobs: int = 0,
    board: str = "",
    square_mm: float | None = None,
    camera_source: str = "",
    progress: Progress | None = None,
) -> SensorRun:
    """The light planes (and, without ``camera``, the camera from the ``chessboard``
    images) as ``kinecal sensor calibrate-planes`` finds them.

    ``folder`` holds one sub-folder per target pose with ``board.png`` and
    ``plane_NNN.png``; ``camera``: intrinsics held fixed (from ``camera_source``).

    Returns
    -------
    SensorRun
        The calibration, the poses skipped and the planes' fit status.

    Raises
    ------
    DataError
        A missing board image, plane numbers beyond ``n_planes``, images of another
        size, too few boards or stripes.
    """
    from kinecal.io import image_files, read_image
    from kinecal.sensor import calibrate_sensor

    say = progress or _quiet
    pose_dirs, boards, sets, m = _pose_folders(folder, n_planes)
    cb_files = image_files(chessboard) if chessboard is not None else []
    say(
        "images",
        f"{len(pose_dirs)} target poses, {sum(len(s) for s in sets)} stripe images, "
        f"{len(cb_files)} chessboard views",
    )
    # Images are read when searched or extracted, on the worker threads, and dropped.
    cb: list[Path | None] = [*cb_files]
    pb: list[Path | None] = [*boards]
    size = None if camera is None else (camera.width, camera.height)
    read = SameSize(read_image, size, camera_source)
    try:
        res = calibrate_sensor(
            LazyImages(cb, read),
            target,
            LazyImages(pb, read),
            [LazyImages([s.get(i) for i in range(m)], read) for s in sets],
            n_planes=m,
            camera=camera,
            model=model,
            k3=k3,
            detector=detector,
            jobs=jobs,
        )
    except DataError as exc:  # which folder, and which board was looked for
        where = chessboard if "camera views" in str(exc) else folder
        raise DataError(f"{where}: {exc} (--board {board})") from None
    _board_distance_checked(res.bundle.T_cam_board, target, folder)
    skipped = sorted(set(range(len(pose_dirs))) - set(res.plane_poses))
    pc = res.planes
    status = {k: pc.status.count(k) for k in sorted(set(pc.status))}
    info: dict[str, Any] = {
        "method": "bundle adjustment of "
        + ("camera, " if camera is None else "")
        + "board poses and light planes (corners and stripes)",
        "planes_method": model,
        "target_poses": len(res.plane_poses),
        "plane_fit_rms_mm": {
            "mean": pc.mean_rms_mm,
            "max": float(np.nanmax(pc.rms_mm)),
        },
        "plane_std_mm": {"median": float(np.nanmedian(np.asarray(pc.std_mm)))},
        "plane_status": status,
        "sigma_stripe_px": res.sigma_stripe_px,
        "stripe_outliers": res.stripe_outliers,
    }
    if camera is None:
        info["camera"] = camera_info(res.camera, target, square_mm)
    return SensorRun(res, tuple(boards[k] for k in skipped), status, info)


def _board_distance_checked(
    T: np.ndarray, target: ChessboardTarget, where: Any
) -> None:
    """Refuse boards found within 5 mm of the camera centre: a --square-mm in metres
    (0.0025 for 2.5 mm) scales the light planes 1000 times down, without an error."""
    dist_mm = float(np.median(np.linalg.norm(T[:, :3, 3], axis=1))) * 1e3
    if dist_mm < 5.0:
        raise DataError(
            f"{where}: the chessboard would be {dist_mm:.3g} mm from the camera with "
            f"--square-mm {target.square * 1e3:g}; expected the square's side in mm "
            "(a board closer than 5 mm cannot be seen sharply: metres given?)."
        )


def _pose_folders(
    folder: str | Path, n_planes: int | None
) -> tuple[list[Path], list[Path], list[dict[int, Path]], int]:
    """The target poses' folders, their board images, their stripe images by plane
    number, and the number of planes."""
    from kinecal.io import image_files

    root = Path(folder)
    pose_dirs = sorted(p for p in root.iterdir() if p.is_dir()) if root.is_dir() else []
    if not pose_dirs:
        raise DataError(f"{folder}: expected one sub-folder per target pose")
    boards, sets = [], []
    highest = 0
    for d in pose_dirs:
        if not (d / "board.png").is_file():
            raise DataError(
                f"{d}: missing board.png (the chessboard image of this pose)"
            )
        files = image_files(d, "plane_*.png")
        idx = plane_indices(files)
        highest = max(highest, max(idx) + 1)
        boards.append(d / "board.png")
        sets.append(dict(zip(idx, files)))
    m = n_planes or highest
    if m < highest:
        raise DataError(
            f"{folder}: plane images up to number {highest - 1}, but --n-planes {m}"
        )
    return pose_dirs, boards, sets, m


def plane_index(path: Path) -> int:
    """The light-plane number of a stripe image ``plane_NNN.png``."""
    m = re.fullmatch(r"plane_(\d+)", path.stem)
    if not m:
        raise DataError(
            f"{path}: file name; expected plane_NNN.png, NNN the light-plane number "
            "(e.g. plane_007.png); move other files out of the folder."
        )
    return int(m.group(1))


def plane_indices(files: Sequence[Path]) -> list[int]:
    """The light-plane numbers of stripe images; two images of one plane are refused."""
    seen: dict[int, Path] = {}
    for f in files:
        i = plane_index(f)
        if i in seen:
            raise DataError(
                f"{f}: light plane {i} again (also {seen[i].name}); expected one "
                "image per plane."
            )
        seen[i] = f
    return list(seen)


def read_scan_image(path: Path) -> np.ndarray:
    """A stripe image: grey PNGs by kinecal's fast decoder, anything else by OpenCV
    (:func:`kinecal.io.read_image`, which also says what is wrong with a file)."""
    from kinecal.io import read_image
    from kinecal.sensor import decode_grey_png

    try:
        img = decode_grey_png(Path(path).read_bytes())
    except OSError:
        img = None
    return read_image(path) if img is None else img


class LazyImages(Sequence[Any]):
    """Image files read on access (``None`` entries stay ``None``)."""

    def __init__(
        self, paths: list[Path | None], reader: Callable[[Path], np.ndarray]
    ) -> None:
        self._paths, self._read = paths, reader

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, i: Any) -> Any:
        p = self._paths[i]
        return None if p is None else self._read(p)


class SameSize:
    """A reader of images that refuses one whose size differs from ``expected`` (the
    sensor file's camera, ``(width, height)``) or, without it, from the first image
    read: a binned or cropped image would be mapped through the wrong pixels (a 2x2
    binned scan with a full-size sensor file fitted a 15 mm sphere as 18 mm)."""

    def __init__(
        self,
        reader: Callable[[Path], np.ndarray],
        expected: tuple[int, int] | None = None,
        source: str = "",
    ) -> None:
        self._read, self._size, self._source = reader, expected, source
        self._first: Path | None = None
        self._lock = threading.Lock()

    def __call__(self, path: Path) -> np.ndarray:
        img = self._read(path)
        size = (int(img.shape[1]), int(img.shape[0]))
        with self._lock:
            if self._size is None:
                self._size, self._first = size, path
        if size != self._size:
            w, h = self._size
            what = (
                f"the first image read, {self._first}"
                if self._first is not None
                else f"the camera of {self._source}"
            )
            raise DataError(
                f"{path}: {size[0]}x{size[1]} pixels; expected {w}x{h}, the size of "
                f"{what} (binned, cropped or another camera's images need a sensor "
                "file calibrated at their size)."
            )
        return img
