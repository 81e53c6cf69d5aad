"""``kinecal sensor`` calibration and sphere-fit commands.

Registered on the ``sensor`` group by :mod:`kinecal.cli._sensor`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from kinecal.cli._common import FiniteFloat, Progress, common_options, jobs_option

if TYPE_CHECKING:
    pass

_BOARD_HELP = "Chessboard inner corners COLSxROWS (one even, one odd count)."
_K3_HELP = (
    "k3: estimated only where the data determine it (auto), always (free) or never "
    "(fixed, k3 = 0)."
)
_DETECTOR_HELP = (
    "Board corners: OpenCV's classic detector, and its sector-based one where the "
    "classic one finds no board (auto); or only one of them. Corners refined by "
    "cornerSubPix."
)


def _k3_option(f: Any) -> Any:
    return click.option(
        "--k3",
        type=click.Choice(["auto", "free", "fixed"]),
        default="auto",
        show_default=True,
        help=_K3_HELP,
    )(f)


def _detector_option(f: Any) -> Any:
    return click.option(
        "--detector",
        type=click.Choice(["auto", "classic", "sb"]),
        default="auto",
        show_default=True,
        help=_DETECTOR_HELP,
    )(f)


@click.command("fit-sphere")
@click.argument("cloud", type=click.Path(dir_okay=False))
@click.option(
    "--radius-mm",
    type=float,
    default=None,
    help="Known radius [mm]: a prior for the segmentation, and only the centre is fitted.",
)
@click.option(
    "--outlier-k",
    type=FiniteFloat(0.0),
    default=4.0,
    show_default=True,
    help="Reject points further than K robust std from the sphere (0: keep all).",
)
@click.option(
    "--no-segment",
    is_flag=True,
    help="Skip the RANSAC segmentation (the cloud holds the sphere only).",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def fit_sphere_cmd(
    cloud: str,
    radius_mm: float | None,
    outlier_k: float,
    no_segment: bool,
    as_json: bool,
) -> None:
    """Fit a sphere to CLOUD.csv (``x_mm, y_mm, z_mm``), segmented from what surrounds it.

    With --json prints {"center_mm": [x, y, z], "radius_mm", "rms_mm", "n"} (n: points
    used, after segmentation and outlier rejection) and "center_std_mm",
    "radius_std_mm", "cap_half_angle_deg", "n_points". Points on a line or a plane (one
    circle), or too flat for their noise, are refused (exit 2).
    """
    import numpy as np

    from kinecal.errors import DataError
    from kinecal.io import read_cloud
    from kinecal.sensor import fit_sphere

    if radius_mm is not None and not radius_mm > 0:
        raise click.BadParameter(
            f"must be positive, got {radius_mm}", param_hint="--radius-mm"
        )
    P = read_cloud(cloud)
    if len(P) >= 5 and np.abs(P).max() * 1e3 < 5.0 and np.ptp(P, axis=0).max() > 0:
        raise DataError(
            f"{cloud}: columns x_mm, y_mm, z_mm: every value is below 5, which looks "
            "like metres; convert to millimetres."
        )
    try:
        f = fit_sphere(
            P,
            radius=None if radius_mm is None else radius_mm * 1e-3,
            outlier_k=outlier_k if outlier_k > 0 else None,
            segment=not no_segment,
        )
    except DataError as exc:
        raise DataError(f"{cloud}: {exc}") from None
    std = f.center_std * 1e3
    if as_json:
        click.echo(
            json.dumps(
                {
                    "center_mm": (f.center * 1e3).tolist(),
                    "radius_mm": f.radius * 1e3,
                    "rms_mm": f.rms * 1e3,
                    "n": f.n,
                    "center_std_mm": std.tolist(),
                    "radius_std_mm": f.radius_std * 1e3,
                    "cap_half_angle_deg": float(np.degrees(f.cap_half_angle)),
                    "n_points": int(f.inliers.size),
                }
            )
        )
        return
    click.echo("centre  x {:.4f}  y {:.4f}  z {:.4f}  mm".format(*(f.center * 1e3)))
    click.echo("  std   x {:.5f}  y {:.5f}  z {:.5f}  mm".format(*std))
    click.echo(
        f"radius  {f.radius * 1e3:.4f} mm"
        + (" (fixed)" if radius_mm else f"  std {f.radius_std * 1e3:.5f} mm")
    )
    click.echo(
        f"rms     {f.rms * 1e3:.5f} mm over {f.n} of {f.inliers.size} points; cap "
        f"half-angle {np.degrees(f.cap_half_angle):.1f} deg"
    )


def _camera_info(cc: Any, tgt: Any, square_mm: float) -> dict[str, Any]:
    from collections import Counter

    return {
        "method": "bundle adjustment from Zhang's start (OpenCV calibrateCamera)",
        "images": len(cc.used),
        "rms_reprojection_px": cc.rms_px,
        "sigma_corner_px": cc.sigma_px,
        "std": cc.std,
        "fixed": list(cc.fixed),
        "k3_test": cc.k3_test,
        "detectors": dict(Counter(cc.detectors)),
        "board": {"cols": tgt.cols, "rows": tgt.rows, "square_mm": square_mm},
    }


def _print_camera(cc: Any) -> None:
    cam = cc.camera
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
            click.echo(f"  {name:3s} {getattr(cam, name):14.6f}  fixed{why}")
        else:
            click.echo(f"  {name:3s} {getattr(cam, name):14.6f}  ± {cc.std[name]:.6f}")


@click.command("calibrate-camera")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--board", default="10x7", show_default=True, help=_BOARD_HELP)
@click.option("--square-mm", type=float, default=2.5, show_default=True)
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="CAMERA.yaml"
)
@_k3_option
@_detector_option
@jobs_option("Threads searching the chessboards")
@click.option("--force", is_flag=True)
@common_options
def calibrate_camera_cmd(
    folder: str,
    board: str,
    square_mm: float,
    out: str,
    k3: str,
    detector: str,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Camera intrinsics from the chessboard images in FOLDER (*.png): Zhang's method
    refined by a bundle adjustment; standard deviations from the residuals."""
    from kinecal.cli._sensor_args import SameSize, _board, _LazyImages
    from kinecal.errors import DataError
    from kinecal.io import image_files, read_image, save_sensor
    from kinecal.sensor import calibrate_camera

    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    files = image_files(folder)
    prog("images", f"{len(files)} in {folder}")
    paths: list[Path | None] = [*files]
    imgs = _LazyImages(paths, SameSize(read_image))
    try:
        res = calibrate_camera(imgs, tgt, jobs=jobs, k3=k3, detector=detector)
    except DataError as exc:  # the folder instead of the function's name
        text = str(exc)
        if not text.startswith("calibrate_camera: "):
            raise
        raise DataError(
            f"{folder}: {text.removeprefix('calibrate_camera: ')} (--board {board})"
        ) from None
    skipped = sorted(set(range(len(files))) - set(res.used) - set(res.rejected))
    for k in skipped:
        click.echo(
            f"warning: {files[k]}: chessboard not found; image skipped", err=True
        )
    for k in res.rejected:
        click.echo(
            f"warning: {files[k]}: corners inconsistent with the other views "
            "(re-projection error far above theirs); image left out",
            err=True,
        )
    save_sensor(out, res.camera, _camera_info(res, tgt, square_mm), force=force)
    click.echo(
        f"re-projection RMS {res.rms_px:.4f} px over {len(res.used)} images "
        f"(corner std {res.sigma_px:.4f} px)"
    )
    _print_camera(res)
    click.echo(f"-> {out}", err=True)


@click.command("calibrate-planes")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option(
    "--camera",
    "camera_file",
    type=click.Path(dir_okay=False),
    help="Camera (or sensor) YAML: the intrinsics, held fixed (without --chessboard).",
)
@click.option(
    "--chessboard",
    "chessboard",
    type=click.Path(file_okay=False),
    help="The camera's chessboard images: camera and planes adjusted together.",
)
@click.option("--board", default="10x7", show_default=True, help=_BOARD_HELP)
@click.option("--square-mm", type=float, default=2.5, show_default=True)
@click.option(
    "--n-planes",
    type=click.IntRange(min=1),
    default=None,
    help="Number of light planes [default: the highest plane number + 1].",
)
@click.option(
    "--model",
    type=click.Choice(["auto", "free", "rotary"]),
    default="auto",
    show_default=True,
    help="Planes fitted on their own, about the mirror axis, or both.",
)
@_k3_option
@_detector_option
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="SENSOR.yaml"
)
@jobs_option("Threads reading the images, searching the boards, extracting stripes")
@click.option("--force", is_flag=True)
@common_options
def calibrate_planes_cmd(
    folder: str,
    camera_file: str | None,
    chessboard: str | None,
    board: str,
    square_mm: float,
    n_planes: int | None,
    model: str,
    k3: str,
    detector: str,
    out: str,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Light planes from stripes on the planar target at several poses.

    FOLDER holds one sub-folder per target pose, each with ``board.png`` (the chessboard,
    backlight on) and ``plane_NNN.png`` (light plane NNN, backlight off). With
    --chessboard, one bundle adjustment estimates the intrinsics, every board pose and
    the planes from the corners and the stripes together; with --camera alone the
    intrinsics are held and the target poses and planes adjusted.
    """
    import numpy as np

    from kinecal.cli._sensor_args import (
        SameSize,
        _board,
        _LazyImages,
        _plane_index,
    )
    from kinecal.errors import DataError
    from kinecal.io import image_files, load_sensor, read_image, save_sensor
    from kinecal.sensor import Camera, calibrate_sensor

    if camera_file is None and chessboard is None:
        raise click.UsageError("give --chessboard (joint calibration) or --camera")
    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    cam = None
    if camera_file is not None and chessboard is None:
        loaded = load_sensor(camera_file, need_planes=False)
        cam = loaded if isinstance(loaded, Camera) else loaded.camera
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
        idx = [_plane_index(f) for f in files]
        highest = max(highest, max(idx) + 1)
        boards.append(d / "board.png")
        sets.append(dict(zip(idx, files)))
    m = n_planes or highest
    if m < highest:
        raise DataError(
            f"{folder}: plane images up to number {highest - 1}, but --n-planes {m}"
        )
    cb_files = image_files(chessboard) if chessboard is not None else []
    prog(
        "images",
        f"{len(pose_dirs)} target poses, {sum(len(s) for s in sets)} stripe images, "
        f"{len(cb_files)} chessboard views",
    )
    # Images are read when searched or extracted, on the worker threads, and dropped.
    cb: list[Path | None] = [*cb_files]
    pb: list[Path | None] = [*boards]
    read = SameSize(
        read_image, None if cam is None else (cam.width, cam.height), str(camera_file)
    )
    try:
        res = calibrate_sensor(
            _LazyImages(cb, read),
            tgt,
            _LazyImages(pb, read),
            [_LazyImages([s.get(i) for i in range(m)], read) for s in sets],
            n_planes=m,
            camera=cam,
            model=model,
            k3=k3,
            detector=detector,
            jobs=jobs,
        )
    except DataError as exc:  # which folder, and which board was looked for
        where = chessboard if "camera views" in str(exc) else folder
        raise DataError(f"{where}: {exc} (--board {board})") from None
    for k in sorted(set(range(len(pose_dirs))) - set(res.plane_poses)):
        click.echo(
            f"warning: {boards[k]}: chessboard not found; pose skipped", err=True
        )
    pc = res.planes
    status = {k: pc.status.count(k) for k in sorted(set(pc.status))}
    info: dict[str, Any] = {
        "method": "bundle adjustment of "
        + ("camera, " if cam is None else "")
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
    if cam is None:
        info["camera"] = _camera_info(res.camera, tgt, square_mm)
    save_sensor(out, res.sensor, info, force=force)
    if cam is None:
        cc = res.camera
        click.echo(
            f"re-projection RMS {cc.rms_px:.4f} px over {len(cc.used)} views and "
            f"{len(res.plane_poses)} target poses (corner std {cc.sigma_px:.4f} px)"
        )
        _print_camera(cc)
    click.echo(
        f"{len(pc.planes)} light planes from {len(res.plane_poses)} target poses: fit "
        f"RMS {pc.mean_rms_mm:.4f} mm (mean), {np.nanmax(pc.rms_mm):.4f} mm (max); "
        f"stripe std {res.sigma_stripe_px:.3f} px; "
        + ", ".join(f"{v} {k}" for k, v in status.items())
    )
    click.echo(f"-> {out}", err=True)


COMMANDS = (fit_sphere_cmd, calibrate_camera_cmd, calibrate_planes_cmd)
