"""``kinecal sensor`` calibration and sphere-fit commands.

Registered on the ``sensor`` group by :mod:`kinecal.cli._sensor`.
"""

from __future__ import annotations

import json
from typing import Any

import click

from kinecal.cli._common import (
    FiniteFloat,
    Progress,
    common_options,
    jobs_option,
    option_table,
)

_BOARD_HELP = "Chessboard inner corners COLSxROWS (one even, one odd count)."
# fmt: off
_K3 = (("--k3",), {"type": click.Choice(["auto", "free", "fixed"]), "default": "auto",
    "show_default": True, "help": "k3: estimated only where the data determine it "
    "(auto), always (free) or never (fixed, k3 = 0)."})
_DETECTOR = (("--detector",), {"type": click.Choice(["auto", "classic", "sb"]),
    "default": "auto", "show_default": True, "help": "Board corners: OpenCV's classic "
    "detector, and its sector-based one where the classic one finds no board (auto); or "
    "only one of them. Corners refined by cornerSubPix."})
_BOARD = (("--board",), {"default": "10x7", "show_default": True, "help": _BOARD_HELP})
_SQUARE = (("--square-mm",), {"type": float, "default": 2.5, "show_default": True})
_FORCE = (("--force",), {"is_flag": True})
_FIT_SPHERE: list[Any] = [
    (("--radius-mm",), {"type": float, "default": None, "help": "Known radius [mm]: a "
        "prior for the segmentation, and only the centre is fitted."}),
    (("--outlier-k",), {"type": FiniteFloat(0.0), "default": 4.0, "show_default": True,
        "help": "Reject points further than K robust std from the sphere (0: keep all)."}),
    (("--no-segment",), {"is_flag": True, "help": "Skip the RANSAC segmentation (the "
        "cloud holds the sphere only)."}),
    (("--json", "as_json"), {"is_flag": True, "help": "Print one JSON object."}),
]
_CAMERA: list[Any] = [
    _BOARD, _SQUARE,
    (("--out", "out"), {"required": True, "type": click.Path(dir_okay=False),
        "help": "CAMERA.yaml"}),
    _K3, _DETECTOR, jobs_option("Threads searching the chessboards"), _FORCE,
]
_PLANES: list[Any] = [
    (("--camera", "camera_file"), {"type": click.Path(dir_okay=False), "help": "Camera "
        "(or sensor) YAML: the intrinsics, held fixed (without --chessboard)."}),
    (("--chessboard", "chessboard"), {"type": click.Path(file_okay=False), "help": "The "
        "camera's chessboard images: camera and planes adjusted together."}),
    _BOARD, _SQUARE,
    (("--n-planes",), {"type": click.IntRange(min=1), "default": None, "help": "Number "
        "of light planes [default: the highest plane number + 1]."}),
    (("--model",), {"type": click.Choice(["auto", "free", "rotary"]), "default": "auto",
        "show_default": True, "help": "Planes fitted on their own, about the mirror "
        "axis, or both."}),
    _K3, _DETECTOR,
    (("--out", "out"), {"required": True, "type": click.Path(dir_okay=False),
        "help": "SENSOR.yaml"}),
    jobs_option("Threads reading the images, searching the boards, extracting stripes"),
    _FORCE,
]
# fmt: on


@click.command("fit-sphere")
@click.argument("cloud", type=click.Path(dir_okay=False))
@option_table(_FIT_SPHERE)
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
    from kinecal.workflows import fit_cloud_sphere
    from kinecal.workflows._sensor import sphere_dict, sphere_lines

    if radius_mm is not None and not radius_mm > 0:
        raise click.BadParameter(
            f"must be positive, got {radius_mm}", param_hint="--radius-mm"
        )
    f = fit_cloud_sphere(
        cloud, radius_mm=radius_mm, outlier_k=outlier_k, segment=not no_segment
    )
    if as_json:
        click.echo(json.dumps(sphere_dict(f)))
        return
    click.echo("\n".join(sphere_lines(f, fixed=bool(radius_mm))))


@click.command("calibrate-camera")
@click.argument("folder", type=click.Path(file_okay=False))
@option_table(_CAMERA)
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
    from kinecal.cli._sensor_args import _board
    from kinecal.io import save_sensor
    from kinecal.workflows import calibrate_camera_images

    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    run = calibrate_camera_images(
        folder, tgt, k3=k3, detector=detector, jobs=jobs, board=board,
        square_mm=square_mm, progress=prog,
    )  # fmt: skip
    for line in run.warning_lines():
        click.echo(line, err=True)
    lines = run.summary_lines()  # before the file (issue 35)
    save_sensor(out, run.result.camera, run.info, force=force)
    click.echo("\n".join(lines))
    click.echo(f"-> {out}", err=True)


@click.command("calibrate-planes")
@click.argument("folder", type=click.Path(file_okay=False))
@option_table(_PLANES)
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

    from kinecal.cli._sensor_args import _board
    from kinecal.io import load_sensor, save_sensor
    from kinecal.sensor import Camera
    from kinecal.workflows import calibrate_sensor_images

    if camera_file is None and chessboard is None:
        raise click.UsageError("give --chessboard (joint calibration) or --camera")
    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    cam = None
    if camera_file is not None and chessboard is None:
        loaded = load_sensor(camera_file, need_planes=False)
        cam = loaded if isinstance(loaded, Camera) else loaded.camera
    run = calibrate_sensor_images(
        folder, tgt, camera=cam, chessboard=chessboard, n_planes=n_planes,
        model=model, k3=k3, detector=detector, jobs=jobs, board=board,
        square_mm=square_mm, camera_source=str(camera_file), progress=prog,
    )  # fmt: skip
    for f in run.skipped:
        click.echo(f"warning: {f}: chessboard not found; pose skipped", err=True)
    lines = run.summary_lines(camera_estimated=cam is None)  # before the file
    save_sensor(out, run.result.sensor, run.info, force=force)
    click.echo("\n".join(lines))
    click.echo(f"-> {out}", err=True)


COMMANDS = (fit_sphere_cmd, calibrate_camera_cmd, calibrate_planes_cmd)
