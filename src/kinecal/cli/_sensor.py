"""``kinecal sensor ...``: the 3D rotary laser sensor, from images to sphere centres."""

from __future__ import annotations

import click

from kinecal.cli._common import Progress, common_options, jobs_option
from kinecal.cli._sensor_args import _LazyImages, _plane_index


@click.group()
def sensor() -> None:
    """The 3D rotary laser sensor: stripes, calibration, reconstruction, sphere fits."""


@sensor.command()
@click.argument("image", type=click.Path(dir_okay=False))
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="CENTERS.csv"
)
@click.option("--force", is_flag=True, help="Overwrite OUT.")
def stripes(image: str, out: str, force: bool) -> None:
    """Sub-pixel stripe centres of one stripe image: ``u_px, v_px, peak`` per row.

    Pixel-centre convention: pixel (0, 0) spans -0.5..0.5 in u and v.
    """
    from kinecal.io import read_image, write_stripes
    from kinecal.sensor import extract_stripes

    img = read_image(image)
    st = extract_stripes(img)
    write_stripes(out, st, force=force)
    click.echo(f"{st.shape[0]} stripe centres -> {out}", err=True)


@sensor.command()
@click.argument("folder", type=click.Path(file_okay=False))
@click.option("--sensor", "sensor_file", required=True, type=click.Path(dir_okay=False))
@click.option(
    "--out", "out", required=True, type=click.Path(dir_okay=False), help="CLOUD.csv"
)
@jobs_option("Threads reading the images and extracting the stripes")
@click.option("--force", is_flag=True)
@common_options
def reconstruct(
    folder: str, sensor_file: str, out: str, jobs: int, force: bool, quiet: bool
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
    cloud = sen.scan(_LazyImages(list(files), read_image), idx, jobs=jobs)
    write_cloud(
        out,
        cloud.points,
        {"u_px": cloud.uv[:, 0], "v_px": cloud.uv[:, 1], "plane": cloud.plane},
        force=force,
    )
    click.echo(f"{cloud.points.shape[0]} points -> {out}", err=True)


def _register() -> None:
    """The calibration, sphere-fit and simulation commands live in their own modules."""
    from kinecal.cli import _sensor_calib, _sensor_sim

    for cmd in (*_sensor_calib.COMMANDS, *_sensor_sim.COMMANDS):
        sensor.add_command(cmd)


_register()
