"""``kinecal sensor ...``: the 3D rotary laser sensor, from images to sphere centres."""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from kinecal.cli._common import Progress, common_options, jobs_option

if TYPE_CHECKING:
    import numpy as np

_BOARD_HELP = "Chessboard inner corners COLSxROWS (one even, one odd count)."


def _board(text: str, square_mm: float) -> Any:
    from kinecal.sensor import ChessboardTarget

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise click.BadParameter(
            f"expected COLSxROWS, e.g. 10x7; got {text!r}", param_hint="--board"
        )
    if square_mm <= 0:
        raise click.BadParameter("must be positive", param_hint="--square-mm")
    return ChessboardTarget(int(m.group(1)), int(m.group(2)), square_mm * 1e-3)


def _plane_index(path: Path) -> int:
    m = re.search(r"(\d+)\D*$", path.stem)
    if not m:
        from kinecal.errors import DataError

        raise DataError(
            f"{path}: stripe images must end with their light-plane number, e.g. plane_007.png"
        )
    return int(m.group(1))


def _triple(text: str, name: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(t) for t in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3:
        raise click.BadParameter(f"expected X,Y,Z; got {text!r}", param_hint=name)
    return vals


@click.group()
def sensor() -> None:
    """The 3D rotary laser sensor: stripes, calibration, reconstruction, sphere fits."""


_METHOD_HELP = (
    "Stripe extractor: 'ridge' (Hessian ridge detector, any direction) or 'rows' "
    "(the first per-row centroid, near-vertical stripes only; for comparisons)."
)


@sensor.command()
@click.argument("image", type=click.Path(dir_okay=False))
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="CENTERS.csv"
)
@click.option(
    "--method",
    type=click.Choice(["ridge", "rows"]),
    default="ridge",
    show_default=True,
    help=_METHOD_HELP,
)
@click.option(
    "--sigma-px",
    type=float,
    default=None,
    help="Smoothing scale of the ridge detector [px] (default: 1.5, or the stripe's own "
    "Gaussian width when it is wider than 2.4 px).",
)
@click.option("--force", is_flag=True, help="Overwrite OUT.")
def stripes(
    image: str, out: str, method: str, sigma_px: float | None, force: bool
) -> None:
    """Sub-pixel stripe centres of one stripe image, one per cross-section.

    Writes ``u_px, v_px, nx, ny, width_px, peak, flags``: the centre, the unit normal
    across the stripe, its width (FWHM) [px], its amplitude over the background [grey
    levels] and flag bits (1 saturated: centre from a fit to the unsaturated flanks,
    2 saturated and the fit failed, 4 near the image border, 8 a weaker ridge close
    by: a reflection). One centre per image row where the stripe runs more vertically
    than horizontally, per column elsewhere. Pixel-centre convention: pixel (0, 0)
    spans -0.5..0.5 in u and v.
    """
    from kinecal.io import read_image, write_stripes
    from kinecal.sensor import extract_stripes

    options: dict[str, Any] = {"method": method}
    if sigma_px is not None:
        if method != "ridge":
            raise click.BadParameter("only for --method ridge", param_hint="--sigma-px")
        options["sigma_px"] = sigma_px
    img = read_image(image)
    st = extract_stripes(img, **options)
    write_stripes(out, st, force=force)
    click.echo(f"{st.shape[0]} stripe centres -> {out}", err=True)


@sensor.command("fit-sphere")
@click.argument("cloud", type=click.Path(dir_okay=False))
@click.option(
    "--radius-mm", type=float, default=None, help="Known radius: fit the centre only."
)
@click.option(
    "--outlier-k",
    type=float,
    default=4.0,
    show_default=True,
    help="Reject points further than K robust std from the sphere (0: keep all).",
)
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
def fit_sphere_cmd(
    cloud: str, radius_mm: float | None, outlier_k: float, as_json: bool
) -> None:
    """Fit a sphere to CLOUD.csv (``x_mm, y_mm, z_mm``): centre, radius, RMS, n.

    With --json prints {"center_mm": [x, y, z], "radius_mm", "rms_mm", "n"} (n: points
    used, after outlier rejection).
    """
    import numpy as np

    from kinecal.io import read_cloud
    from kinecal.sensor import fit_sphere

    P = read_cloud(cloud)
    f = fit_sphere(
        P,
        radius=None if radius_mm is None else radius_mm * 1e-3,
        outlier_k=outlier_k if outlier_k > 0 else None,
    )
    if as_json:
        click.echo(
            json.dumps(
                {
                    "center_mm": (f.center * 1e3).tolist(),
                    "radius_mm": f.radius * 1e3,
                    "rms_mm": f.rms * 1e3,
                    "n": f.n,
                }
            )
        )
        return
    std = f.center_std * 1e3
    click.echo("centre  x {:.4f}  y {:.4f}  z {:.4f}  mm".format(*(f.center * 1e3)))
    click.echo("  std   x {:.5f}  y {:.5f}  z {:.5f}  mm".format(*std))
    click.echo(f"radius  {f.radius * 1e3:.4f} mm" + (" (fixed)" if radius_mm else ""))
    click.echo(
        f"rms     {f.rms * 1e3:.5f} mm over {f.n} points; {f.n_outliers} outliers"
    )
    if not np.all(np.isfinite(std)):
        click.echo("warning: the centre is not determined by these points", err=True)


@sensor.command("calibrate-camera")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--board", default="10x7", show_default=True, help=_BOARD_HELP)
@click.option("--square-mm", type=float, default=2.5, show_default=True)
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="CAMERA.yaml"
)
@jobs_option("Threads searching the chessboards")
@click.option("--force", is_flag=True)
@common_options
def calibrate_camera_cmd(
    folder: str,
    board: str,
    square_mm: float,
    out: str,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Camera intrinsics by Zhang's method from the chessboard images in FOLDER (*.png)."""
    from kinecal.io import image_files, read_image, save_sensor
    from kinecal.sensor import calibrate_camera

    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    files = image_files(folder)
    prog("images", f"{len(files)} in {folder}")
    res = calibrate_camera([read_image(f) for f in files], tgt, jobs=jobs)
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
    cam = res.camera
    info = {
        "method": "Zhang (OpenCV calibrateCameraExtended)",
        "images": len(res.used),
        "rms_reprojection_px": res.rms_px,
        "std": res.std,
        "board": {"cols": tgt.cols, "rows": tgt.rows, "square_mm": square_mm},
    }
    save_sensor(out, cam, info, force=force)
    click.echo(f"re-projection RMS {res.rms_px:.4f} px over {len(res.used)} images")
    for name in ("fx", "fy", "u0", "v0", "k1", "k2", "k3", "p1", "p2"):
        click.echo(f"  {name:3s} {getattr(cam, name):14.6f}  ± {res.std[name]:.6f}")
    click.echo(f"-> {out}", err=True)


@sensor.command("calibrate-planes")
@click.argument("folder", type=click.Path(file_okay=False))
@click.option(
    "--camera",
    "camera_file",
    required=True,
    type=click.Path(dir_okay=False),
    help="Camera (or sensor) YAML from calibrate-camera.",
)
@click.option("--board", default="10x7", show_default=True, help=_BOARD_HELP)
@click.option("--square-mm", type=float, default=2.5, show_default=True)
@click.option(
    "--n-planes",
    type=int,
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
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="SENSOR.yaml"
)
@jobs_option("Threads extracting the stripes")
@click.option("--force", is_flag=True)
@common_options
def calibrate_planes_cmd(
    folder: str,
    camera_file: str,
    board: str,
    square_mm: float,
    n_planes: int | None,
    model: str,
    out: str,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Light planes from stripes on the planar target at several poses.

    FOLDER holds one sub-folder per target pose, each with ``board.png`` (the chessboard,
    backlight on) and ``plane_NNN.png`` (light plane NNN, backlight off).
    """
    import numpy as np

    from kinecal.errors import DataError
    from kinecal.io import image_files, load_sensor, read_image, save_sensor
    from kinecal.sensor import Camera, Sensor, board_pose, calibrate_planes

    prog = Progress(quiet)
    tgt = _board(board, square_mm)
    loaded = load_sensor(camera_file, need_planes=False)
    cam = loaded if isinstance(loaded, Camera) else loaded.camera
    poses_dirs = (
        sorted(p for p in Path(folder).iterdir() if p.is_dir())
        if Path(folder).is_dir()
        else []
    )
    if not poses_dirs:
        raise DataError(f"{folder}: expected one sub-folder per target pose")
    poses, sets = [], []
    highest = 0
    for d in poses_dirs:
        if not (d / "board.png").is_file():
            raise DataError(
                f"{d}: missing board.png (the chessboard image of this pose)"
            )
        T = board_pose(read_image(d / "board.png"), cam, tgt)
        if T is None:
            click.echo(
                f"warning: {d / 'board.png'}: chessboard not found; pose skipped",
                err=True,
            )
            continue
        files = image_files(d, "plane_*.png")
        idx = [_plane_index(f) for f in files]
        highest = max(highest, max(idx) + 1)
        poses.append(T)
        sets.append(dict(zip(idx, files)))
        prog("pose", f"{d.name}: {len(files)} stripe images")
    m = n_planes or highest
    if m < highest:
        raise DataError(
            f"{folder}: plane images up to number {highest - 1}, but --n-planes {m}"
        )
    # Each image is read when its stripes are extracted and dropped after: memory stays
    # at one image, not every image of every pose (5 x 120 x 1.3 MB).
    imgs = [_LazyImages([s.get(i) for i in range(m)], read_image) for s in sets]
    res = calibrate_planes(cam, poses, imgs, model=model, jobs=jobs)
    status = {k: res.status.count(k) for k in sorted(set(res.status))}
    info = {
        "planes_method": model,
        "target_poses": len(poses),
        "plane_fit_rms_mm": {
            "mean": res.mean_rms_mm,
            "max": float(np.nanmax(res.rms_mm)),
        },
        "plane_status": status,
    }
    save_sensor(out, Sensor(cam, res.planes), info, force=force)
    click.echo(
        f"{len(res.planes)} light planes from {len(poses)} target poses: fit RMS "
        f"{res.mean_rms_mm:.4f} mm (mean), {np.nanmax(res.rms_mm):.4f} mm (max); "
        + ", ".join(f"{v} {k}" for k, v in status.items())
    )
    click.echo(f"-> {out}", err=True)


@sensor.command()
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--sensor", "sensor_file", required=True, type=click.Path(dir_okay=False))
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="CLOUD.csv"
)
@click.option(
    "--method",
    type=click.Choice(["ridge", "rows"]),
    default="ridge",
    show_default=True,
    help=_METHOD_HELP,
)
@jobs_option("Threads reading the images and extracting the stripes")
@click.option("--force", is_flag=True)
@common_options
def reconstruct(
    folder: str,
    sensor_file: str,
    out: str,
    method: str,
    jobs: int,
    force: bool,
    quiet: bool,
) -> None:
    """Point cloud of one scan: FOLDER holds ``plane_NNN.png`` (light plane NNN).

    Writes ``x_mm, y_mm, z_mm`` in the camera frame plus the pixel and plane of each point.
    """
    import numpy as np

    from kinecal.io import image_files, load_sensor, read_image, write_cloud
    from kinecal.sensor import Sensor

    prog = Progress(quiet)
    sen = load_sensor(sensor_file)
    assert isinstance(sen, Sensor)
    files = image_files(folder, "plane_*.png")
    idx = np.array([_plane_index(f) for f in files])
    prog("images", f"{len(files)} stripe images")
    # Each image is read in the thread that extracts its stripes, and dropped after.
    cloud = sen.scan(
        _LazyImages(list(files), read_image), idx, jobs=jobs, method=method
    )
    write_cloud(
        out,
        cloud.points,
        {"u_px": cloud.uv[:, 0], "v_px": cloud.uv[:, 1], "plane": cloud.plane},
        force=force,
    )
    click.echo(f"{cloud.points.shape[0]} points -> {out}", err=True)


@sensor.command("simulate-scan")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False))
@click.option(
    "--center-mm",
    default="0,0,140",
    show_default=True,
    help="Sphere centre X,Y,Z in the camera frame.",
)
@click.option("--radius-mm", type=float, default=15.001, show_default=True)
@click.option(
    "--every", type=int, default=1, show_default=True, help="Render every K-th plane."
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--force", is_flag=True)
@common_options
def simulate_scan(
    out: str,
    center_mm: str,
    radius_mm: float,
    every: int,
    seed: int,
    force: bool,
    quiet: bool,
) -> None:
    """Render the stripe images of one scan of a ceramic sphere (built-in sensor).

    Writes ``plane_NNN.png``, ``sensor.yaml`` (the true sensor) and ``truth.json``.
    """
    import numpy as np

    from kinecal.io import prepare_output_dir, save_sensor, write_image, write_json
    from kinecal.sensor import StripeRenderer, paper_sensor, sphere_scene

    prog = Progress(quiet)
    sen = paper_sensor()
    c = np.array(_triple(center_mm, "--center-mm")) * 1e-3
    idx = np.arange(0, len(sen.planes), max(every, 1))
    names = [f"plane_{i:03d}.png" for i in idx] + ["sensor.yaml", "truth.json"]
    d = prepare_output_dir(out, names, force=force)
    ren = StripeRenderer(sen.camera, sen.planes)
    scene = sphere_scene(c, radius_mm * 1e-3)
    rng = np.random.default_rng(seed)
    for k, i in enumerate(idx):
        write_image(
            d / f"plane_{i:03d}.png", ren.render(scene, int(i), rng), force=True
        )
        if k % 20 == 0:
            prog("render", f"{k + 1}/{idx.size}")
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


@sensor.command("simulate-calibration")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False))
@click.option(
    "--views", type=int, default=15, show_default=True, help="Chessboard views."
)
@click.option(
    "--poses",
    type=int,
    default=5,
    show_default=True,
    help="Target poses for the planes.",
)
@click.option(
    "--every", type=int, default=1, show_default=True, help="Render every K-th plane."
)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--force", is_flag=True)
@common_options
def simulate_calibration_cmd(
    out: str, views: int, poses: int, every: int, seed: int, force: bool, quiet: bool
) -> None:
    """Render a calibration session of the built-in sensor.

    Writes ``chessboard/view_NN.png`` (for calibrate-camera), ``planes/pose_NN/board.png``
    and ``planes/pose_NN/plane_NNN.png`` (for calibrate-planes) and ``truth_sensor.yaml``.
    """
    import numpy as np

    from kinecal.io import prepare_output_dir, save_sensor, write_image
    from kinecal.sensor import paper_sensor, simulate_calibration

    prog = Progress(quiet)
    sen = paper_sensor()
    d = prepare_output_dir(
        out, ["chessboard", "planes", "truth_sensor.yaml"], force=force
    )
    idx = np.arange(0, len(sen.planes), max(every, 1))
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
    for k, img in enumerate(ses.chessboard_images):
        write_image(d / "chessboard" / f"view_{k:02d}.png", img, force=True)
    for k, (board, imgs) in enumerate(
        zip(ses.plane_board_images, ses.plane_stripe_images)
    ):
        pd = d / "planes" / f"pose_{k:02d}"
        write_image(pd / "board.png", board, force=True)
        for i, img in zip(idx, imgs):
            write_image(pd / f"plane_{i:03d}.png", img, force=True)
    save_sensor(
        d / "truth_sensor.yaml",
        sen,
        {"source": "built-in paper sensor (simulated truth)"},
        force=True,
    )
    click.echo(f"calibration images -> {d}", err=True)


def _read_scan_image(path: Path) -> np.ndarray:
    """A stripe image: grey PNGs by kinecal's fast decoder, anything else by OpenCV
    (:func:`kinecal.io.read_image`, which also says what is wrong with a file)."""
    from kinecal.io import read_image
    from kinecal.sensor import decode_grey_png

    try:
        img = decode_grey_png(Path(path).read_bytes())
    except OSError:
        img = None
    return read_image(path) if img is None else img


class _LazyImages(Sequence):
    """Image files read on access (``None`` entries stay ``None``)."""

    def __init__(self, paths: list[Path | None], reader: Callable[[Path], np.ndarray]):
        self._paths, self._read = paths, reader

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, i):
        p = self._paths[i]
        return None if p is None else self._read(p)
