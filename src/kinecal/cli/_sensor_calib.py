"""``kinecal sensor`` calibration, sphere-fit and simulation commands.

Registered on the ``sensor`` group by :mod:`kinecal.cli._sensor`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from kinecal.cli._common import Progress, common_options, jobs_option

if TYPE_CHECKING:
    import numpy as np

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
    type=float,
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
                why = (
                    f"  (not determined: its std would move the image corner by "
                    f"{cc.k3_test.get('corner_px', float('nan')):.2f} px)"
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
    from kinecal.cli._sensor import _board, _LazyImages
    from kinecal.io import image_files, read_image, save_sensor
    from kinecal.sensor import calibrate_camera

    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    files = image_files(folder)
    prog("images", f"{len(files)} in {folder}")
    paths: list[Path | None] = [*files]
    imgs = _LazyImages(paths, read_image)
    res = calibrate_camera(imgs, tgt, jobs=jobs, k3=k3, detector=detector)
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

    from kinecal.cli._sensor import _board, _LazyImages, _plane_index
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
    res = calibrate_sensor(
        _LazyImages(cb, read_image),
        tgt,
        _LazyImages(pb, read_image),
        [_LazyImages([s.get(i) for i in range(m)], read_image) for s in sets],
        n_planes=m,
        camera=cam,
        model=model,
        k3=k3,
        detector=detector,
        jobs=jobs,
    )
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


class _Writer:
    """Renders (on access) and writes images on ``jobs`` threads of one pool, a
    bounded number at a time (memory: a few images), reporting progress."""

    def __init__(self, jobs: int, prog: Progress) -> None:
        from concurrent.futures import ThreadPoolExecutor

        from kinecal._parallel import available_cpus

        self.n = jobs if jobs > 0 else available_cpus()
        self.pool = ThreadPoolExecutor(self.n)
        self.prog = prog

    def __enter__(self) -> _Writer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.pool.shutdown()

    def write(self, items: list[tuple[Path, Any]], what: str) -> None:
        """Write ``(path, source)`` items: ``source()`` gives the image."""
        from kinecal.io import write_image

        def one(item: tuple[Path, Any]) -> None:
            write_image(item[0], item[1](), force=True, sync=False)

        step = max(1, len(items) // 10)
        for a in range(0, len(items), step):
            for f in [self.pool.submit(one, it) for it in items[a : a + step]]:
                f.result()
            self.prog("render", f"{what} {min(a + step, len(items))}/{len(items)}")


@click.command("simulate-scan")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False))
@click.option(
    "--center-mm",
    default="0,0,140",
    show_default=True,
    help="Sphere centre X,Y,Z in the camera frame.",
)
@click.option("--radius-mm", type=float, default=15.001, show_default=True)
@click.option(
    "--every",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Render every K-th plane.",
)
@click.option("--seed", type=int, default=0, show_default=True)
@jobs_option("Threads rendering and writing the images")
@click.option("--force", is_flag=True)
@common_options
def simulate_scan(
    out: str,
    center_mm: str,
    radius_mm: float,
    every: int,
    seed: int,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Render the stripe images of one scan of a ceramic sphere (built-in sensor).

    Writes ``plane_NNN.png``, ``sensor.yaml`` (the true sensor) and ``truth.json``.
    """
    import numpy as np

    from kinecal.cli._sensor import _triple
    from kinecal.io import prepare_output_dir, save_sensor, write_json
    from kinecal.sensor import (
        RenderedImages,
        StripeRenderer,
        paper_sensor,
        sphere_scene,
    )

    prog = Progress(quiet)
    if not radius_mm > 0:
        raise click.BadParameter(
            f"must be positive, got {radius_mm}", param_hint="--radius-mm"
        )
    sen = paper_sensor()
    c = np.array(_triple(center_mm, "--center-mm")) * 1e-3
    idx = np.arange(0, len(sen.planes), every)
    names = [f"plane_{i:03d}.png" for i in idx] + ["sensor.yaml", "truth.json"]
    d = prepare_output_dir(out, names, force=force)
    ren = StripeRenderer(sen.camera, sen.planes)
    scene = sphere_scene(c, radius_mm * 1e-3)
    imgs = RenderedImages(
        idx.size,
        lambda prep, j, rng: ren.render(prep, int(idx[j]), rng),  # type: ignore[arg-type]
        (seed,),
        lambda: ren.prepare(scene),
    )
    with _Writer(jobs, prog) as w:
        w.write(
            [(d / f"plane_{i:03d}.png", lambda j=j: imgs[j]) for j, i in enumerate(idx)],
            "stripe images",
        )
    save_sensor(
        d / "sensor.yaml",
        sen,
        {"source": "built-in paper sensor (simulated truth)"},
        force=True,
    )
    write_json(
        d / "truth.json",
        {"center_mm": c * 1e3, "radius_mm": radius_mm, "seed": seed},
        force=True,
    )
    click.echo(f"{idx.size} stripe images -> {d}", err=True)


@click.command("simulate-calibration")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False))
@click.option(
    "--views",
    type=click.IntRange(min=1),
    default=15,
    show_default=True,
    help="Chessboard views.",
)
@click.option(
    "--poses",
    type=click.IntRange(min=1),
    default=5,
    show_default=True,
    help="Target poses for the planes.",
)
@click.option(
    "--every",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Render every K-th plane.",
)
@click.option("--seed", type=int, default=0, show_default=True)
@jobs_option("Threads rendering and writing the images")
@click.option("--force", is_flag=True)
@common_options
def simulate_calibration_cmd(
    out: str,
    views: int,
    poses: int,
    every: int,
    seed: int,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Render a calibration session of the built-in sensor.

    Writes ``chessboard/view_NN.png`` (for calibrate-camera), ``planes/pose_NN/board.png``
    and ``planes/pose_NN/plane_NNN.png`` (for calibrate-planes), ``truth_sensor.yaml``
    and ``truth.json`` (the board poses). Images are rendered and written on ``--jobs``
    threads, a few at a time.
    """
    import numpy as np

    from kinecal.io import prepare_output_dir, save_sensor, write_json
    from kinecal.sensor import paper_sensor, simulate_calibration

    prog = Progress(quiet)
    sen = paper_sensor()
    d = prepare_output_dir(
        out, ["chessboard", "planes", "truth_sensor.yaml", "truth.json"], force=force
    )
    idx = np.arange(0, len(sen.planes), every)
    prog(
        "render", f"{views} chessboard views, {poses} target poses x {idx.size} planes"
    )
    ses = simulate_calibration(
        sen,
        np.random.default_rng(seed),
        n_views=views,
        n_plane_poses=poses,
        plane_indices=idx,
    )
    items: list[tuple[Path, Any]] = []
    for k in range(views):
        items.append(
            (
                d / "chessboard" / f"view_{k:02d}.png",
                lambda k=k: ses.chessboard_images[k],
            )
        )
    for k in range(poses):
        pd = d / "planes" / f"pose_{k:02d}"
        items.append((pd / "board.png", lambda k=k: ses.plane_board_images[k]))
    with _Writer(jobs, prog) as w:
        w.write(items, "chessboard images")
        for k in range(poses):  # pose by pose: one prepared scene in memory at a time
            pd = d / "planes" / f"pose_{k:02d}"
            st = ses.plane_stripe_images[k]
            w.write(
                [
                    (pd / f"plane_{i:03d}.png", lambda j=j, st=st: st[j])
                    for j, i in enumerate(idx)
                ],
                f"pose {k + 1}/{poses}: stripe images",
            )
            st.release()  # type: ignore[attr-defined]
    save_sensor(
        d / "truth_sensor.yaml",
        sen,
        {"source": "built-in paper sensor (simulated truth)"},
        force=True,
    )
    write_json(
        d / "truth.json",
        {
            "seed": seed,
            "chessboard_T_cam_board_mm": _poses_mm(ses.chessboard_poses),
            "planes_T_cam_board_mm": _poses_mm(ses.plane_poses),
        },
        force=True,
    )
    click.echo(f"calibration images -> {d}", err=True)


def _poses_mm(T: np.ndarray) -> list[list[list[float]]]:
    out = T.copy()
    out[:, :3, 3] *= 1e3
    return out.tolist()


COMMANDS = (
    fit_sphere_cmd,
    calibrate_camera_cmd,
    calibrate_planes_cmd,
    simulate_scan,
    simulate_calibration_cmd,
)
