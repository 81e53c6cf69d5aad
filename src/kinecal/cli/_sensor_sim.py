"""``kinecal sensor simulate-scan`` and ``simulate-calibration``: rendered sessions.

Registered on the ``sensor`` group by :mod:`kinecal.cli._sensor`. Images render when
they are written, on a pool of threads, a few at a time: memory stays at a few images.
"""

from __future__ import annotations

from typing import Any

import click

from kinecal.cli._common import (
    SEED,
    Progress,
    common_options,
    jobs_option,
    option_table,
)

# fmt: off
_INT = click.IntRange(min=1)
_EVERY = (("--every",), {"type": _INT, "default": 1, "show_default": True,
    "help": "Render every K-th plane."})
_COMMON: list[Any] = [
    (("--seed",), {"type": SEED, "default": 0, "show_default": True}),
    jobs_option("Threads rendering and writing the images"),
    (("--force",), {"is_flag": True}),
]
_OUT = (("--out", "out"), {"required": True, "type": click.Path(file_okay=False)})
_SCAN: list[Any] = [
    _OUT,
    (("--center-mm",), {"default": "0,0,140", "show_default": True, "help": "Sphere "
        "centre X,Y,Z in the camera frame."}),
    (("--radius-mm",), {"type": float, "default": 15.001, "show_default": True}),
    _EVERY, *_COMMON,
]
_SESSION: list[Any] = [
    _OUT,
    (("--views",), {"type": _INT, "default": 25, "show_default": True,
        "help": "Chessboard views."}),
    (("--poses",), {"type": _INT, "default": 5, "show_default": True,
        "help": "Target poses for the planes."}),
    _EVERY, *_COMMON,
]
# fmt: on


@click.command("simulate-scan")
@option_table(_SCAN)
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

    from kinecal.cli._common import parse_floats
    from kinecal.io import prepare_output_dir
    from kinecal.sensor import paper_sensor
    from kinecal.workflows import render_scan
    from kinecal.workflows._sensor_sim import scan_files, scene_problem

    prog = Progress(quiet)
    if not radius_mm > 0:
        raise click.BadParameter(
            f"must be positive, got {radius_mm}", param_hint="--radius-mm"
        )
    sen = paper_sensor()
    x, y, z = parse_floats(center_mm, 3, "--center-mm")
    center = (x, y, z)
    c = np.array(center) * 1e-3
    idx = np.arange(0, len(sen.planes), every)
    problem = scene_problem(sen, c, radius_mm * 1e-3, idx)
    if problem:  # an empty set of images with exit 0 otherwise
        raise click.BadParameter(problem[1], param_hint=problem[0])
    d = prepare_output_dir(out, scan_files(every), force=force)
    ses = render_scan(
        d, center, radius_mm, every=every, seed=seed, jobs=jobs, progress=prog
    )
    click.echo(f"{ses.images} stripe images -> {out}", err=True)  # d: staged (issue 21)


@click.command("simulate-calibration")
@option_table(_SESSION)
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
    from kinecal.io import prepare_output_dir
    from kinecal.workflows import render_calibration_session
    from kinecal.workflows._sensor_sim import CALIBRATION_FILES

    prog = Progress(quiet)
    d = prepare_output_dir(out, list(CALIBRATION_FILES), force=force)
    render_calibration_session(
        d, views=views, poses=poses, every=every, seed=seed, jobs=jobs, progress=prog
    )
    click.echo(f"calibration images -> {out}", err=True)  # d: staged (issue 21)


COMMANDS = (simulate_scan, simulate_calibration_cmd)
