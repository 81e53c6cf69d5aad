"""The rendering workflows of ``kinecal sensor simulate-scan`` and
``simulate-calibration``: a scan of a sphere, or a calibration session, of the built-in
sensor, rendered and written into a folder. Images render when they are written, on a
pool of threads, a few at a time: memory stays at a few images.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from kinecal.sensor import Sensor

__all__ = ["RenderedSession", "render_calibration_session", "render_scan"]

Progress = Callable[[str, str], None]


@dataclass(frozen=True)
class RenderedSession:
    """What a rendering workflow wrote into its folder.

    Attributes
    ----------
    folder : the folder.
    images : how many images.
    files : the files and sub-folders written, relative to ``folder``.
    """

    folder: Path
    images: int
    files: tuple[str, ...]


class _Writer:
    """Renders (on access) and writes images on ``jobs`` threads of one pool, a
    bounded number at a time (memory: a few images), reporting progress."""

    def __init__(self, jobs: int, prog: Progress) -> None:
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


def _quiet(stage: str, detail: str) -> None:
    """No progress display."""


def render_scan(
    folder: Path,
    center_mm: tuple[float, float, float],
    radius_mm: float,
    *,
    every: int = 1,
    seed: int = 0,
    jobs: int = 0,
    progress: Progress | None = None,
) -> RenderedSession:
    """Render the stripe images of one scan of a sphere (centre X, Y, Z [mm] in the
    camera frame, radius [mm]) by the built-in sensor into ``folder`` (which exists), every
    ``every``-th plane: ``plane_NNN.png``, ``sensor.yaml`` (the true sensor) and
    ``truth.json``, as ``kinecal sensor simulate-scan`` does.

    Returns
    -------
    RenderedSession
        The folder and what was written.

    Raises
    ------
    ConfigError
        A sphere the scan cannot see (:func:`scene_problem`: its images would be empty;
        they were written, with the command line's check only).
    """
    from kinecal.errors import ConfigError
    from kinecal.io import save_sensor, write_json
    from kinecal.sensor import (
        RenderedImages,
        StripeRenderer,
        paper_sensor,
        sphere_scene,
    )

    sen = paper_sensor()
    center = np.array(center_mm) * 1e-3
    idx = np.arange(0, len(sen.planes), every)
    problem = scene_problem(sen, center, radius_mm * 1e-3, idx)
    if problem:
        raise ConfigError(f"{problem[0].lstrip('-').replace('-', '_')}: {problem[1]}.")
    ren = StripeRenderer(sen.camera, sen.planes)
    scene = sphere_scene(center, radius_mm * 1e-3)
    imgs = RenderedImages(
        idx.size,
        lambda prep, j, rng: ren.render(prep, int(idx[j]), rng),  # type: ignore[arg-type]
        (seed,),
        lambda: ren.prepare(scene),
    )
    d = Path(folder)
    with _Writer(jobs, progress or _quiet) as w:
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
        {"center_mm": center * 1e3, "radius_mm": radius_mm, "seed": seed},
        force=True,
    )
    names = [f"plane_{i:03d}.png" for i in idx] + ["sensor.yaml", "truth.json"]
    return RenderedSession(d, int(idx.size), tuple(names))


def scene_problem(
    sen: Sensor, c: np.ndarray, r: float, idx: np.ndarray
) -> tuple[str, str] | None:
    """Why the scan cannot see the sphere (its images would be empty), or None: behind
    the camera or around it, outside the image, or missed by every rendered light
    plane. ``c`` (3,) [m] camera frame, ``r`` [m], ``idx`` the rendered planes.

    The problem is (option, message): the option to change, ``--every`` when the
    sphere is lit by planes it skips, else ``--center-mm``."""
    c_mm, r_mm = ", ".join(f"{v:g}" for v in c * 1e3), r * 1e3
    if c[2] - r <= 0:
        return "--center-mm", (
            f"the sphere ({c_mm}) mm, radius {r_mm:g} mm, is not wholly in front of the "
            f"camera; expected Z > {r_mm:g} mm (the working distance is 115-135 mm)"
        )
    cam = sen.camera
    xy = c[:2] / c[2]
    uv = cam.project(c)
    if (
        np.abs(xy).max() > 1.0  # beyond 45 deg off axis (where the distortion folds)
        or not (-0.5 <= uv[0] <= cam.width - 0.5 and -0.5 <= uv[1] <= cam.height - 0.5)
    ):
        return "--center-mm", (
            f"the sphere centre ({c_mm}) mm is outside the camera's "
            f"{cam.width}x{cam.height} image; expected a centre in view, e.g. 0,0,125"
        )
    every = np.arange(len(sen.planes))
    if not np.any(np.abs(sen.planes.distance(c, idx)) < r) and np.any(
        np.abs(sen.planes.distance(c, every)) < r
    ):  # the sphere is lit, by planes --every skips
        return "--every", (
            f"the sphere ({c_mm}) mm, radius {r_mm:g} mm, is lit only by light planes "
            f"that --every skips (it renders {len(idx)} of {len(sen.planes)}): the "
            "images would be empty; expected a smaller --every"
        )
    if not np.any(np.abs(sen.planes.distance(c, idx)) < r):
        return "--center-mm", (
            f"no rendered light plane meets the sphere ({c_mm}) mm, radius {r_mm:g} mm: "
            "the images would be empty; expected a sphere at the working distance "
            "(115-135 mm), e.g. 0,0,125"
        )
    return None


def scan_files(every: int) -> list[str]:
    """The files :func:`render_scan` writes."""
    from kinecal.sensor import paper_sensor

    idx = np.arange(0, len(paper_sensor().planes), every)
    return [f"plane_{i:03d}.png" for i in idx] + ["sensor.yaml", "truth.json"]


def render_calibration_session(
    folder: Path,
    *,
    views: int = 25,
    poses: int = 5,
    every: int = 1,
    seed: int = 0,
    jobs: int = 0,
    progress: Progress | None = None,
) -> RenderedSession:
    """Render a calibration session of the built-in sensor into ``folder`` (which
    exists), as ``kinecal sensor simulate-calibration`` does: ``chessboard/view_NN.png``,
    ``planes/pose_NN/board.png`` and ``plane_NNN.png`` (every ``every``-th plane),
    ``truth_sensor.yaml`` and ``truth.json`` (the board poses).

    Returns
    -------
    RenderedSession
        The folder and what was written.
    """
    from kinecal.io import save_sensor, write_json
    from kinecal.sensor import paper_sensor, simulate_calibration

    say = progress or _quiet
    sen = paper_sensor()
    d = Path(folder)
    idx = np.arange(0, len(sen.planes), every)
    say("render", f"{views} chessboard views, {poses} target poses x {idx.size} planes")
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
    with _Writer(jobs, say) as w:
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
    n = views + poses * (1 + idx.size)
    return RenderedSession(d, n, tuple(CALIBRATION_FILES))


CALIBRATION_FILES = ("chessboard", "planes", "truth_sensor.yaml", "truth.json")


def _poses_mm(T: np.ndarray) -> list[list[list[float]]]:
    out = T.copy()
    out[:, :3, 3] *= 1e3
    return out.tolist()
