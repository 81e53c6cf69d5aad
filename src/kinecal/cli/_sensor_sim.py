"""``kinecal sensor simulate-scan`` and ``simulate-calibration``: rendered sessions.

Registered on the ``sensor`` group by :mod:`kinecal.cli._sensor`. Images render when
they are written, on a pool of threads, a few at a time: memory stays at a few images.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

from kinecal.cli._common import SEED, Progress, common_options, jobs_option

if TYPE_CHECKING:
    import numpy as np


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
        # on an error or Ctrl-C the images not started are dropped, not rendered
        self.pool.shutdown(cancel_futures=exc[0] is not None)

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


def _check_scene(sen: Any, c: Any, r: float, idx: Any) -> None:
    """Refuse a sphere the scan cannot see (an empty set of images with exit 0): behind
    the camera or around it, outside the image, or missed by every rendered light
    plane. ``c`` (3,) [m] camera frame, ``r`` [m], ``idx`` the rendered planes."""
    import numpy as np

    c_mm, r_mm = ", ".join(f"{v:g}" for v in c * 1e3), r * 1e3
    if c[2] - r <= 0:
        raise click.BadParameter(
            f"the sphere ({c_mm}) mm, radius {r_mm:g} mm, is not wholly in front of the "
            f"camera; expected Z > {r_mm:g} mm (the working distance is 115-135 mm)",
            param_hint="--center-mm",
        )
    cam = sen.camera
    xy = c[:2] / c[2]
    uv = cam.project(c)
    if (
        np.abs(xy).max() > 1.0  # beyond 45 deg off axis (where the distortion folds)
        or not (-0.5 <= uv[0] <= cam.width - 0.5 and -0.5 <= uv[1] <= cam.height - 0.5)
    ):
        raise click.BadParameter(
            f"the sphere centre ({c_mm}) mm is outside the camera's "
            f"{cam.width}x{cam.height} image; expected a centre in view, e.g. 0,0,125",
            param_hint="--center-mm",
        )
    if not np.any(np.abs(sen.planes.distance(c, idx)) < r):
        raise click.BadParameter(
            f"no rendered light plane meets the sphere ({c_mm}) mm, radius {r_mm:g} mm: "
            "the images would be empty; expected a sphere at the working distance "
            "(115-135 mm), e.g. 0,0,125",
            param_hint="--center-mm",
        )


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
@click.option("--seed", type=SEED, default=0, show_default=True)
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

    from kinecal.cli._sensor_args import _triple
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
    _check_scene(sen, c, radius_mm * 1e-3, idx)
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
            [
                (d / f"plane_{i:03d}.png", lambda j=j: imgs[j])
                for j, i in enumerate(idx)
            ],
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
    click.echo(f"{idx.size} stripe images -> {out}", err=True)  # d: staged (issue 21)


@click.command("simulate-calibration")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False))
@click.option(
    "--views",
    type=click.IntRange(min=1),
    default=25,
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
@click.option("--seed", type=SEED, default=0, show_default=True)
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
    click.echo(f"calibration images -> {out}", err=True)  # d: staged (issue 21)


def _poses_mm(T: np.ndarray) -> list[list[list[float]]]:
    out = T.copy()
    out[:, :3, 3] *= 1e3
    return out.tolist()


COMMANDS = (simulate_scan, simulate_calibration_cmd)
