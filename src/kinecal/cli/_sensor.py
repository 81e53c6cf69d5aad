"""``kinecal sensor ...``: the 3D rotary laser sensor, from images to sphere centres."""

from __future__ import annotations

from typing import Any

import click

from kinecal.cli._common import Progress, common_options, jobs_option, option_table

_METHOD_HELP = (
    "Stripe extractor: 'ridge' (Hessian ridge detector, any direction) or 'rows' "
    "(the first per-row centroid, near-vertical stripes only; for comparisons)."
)
_method_option = click.option(
    "--method",
    type=click.Choice(["ridge", "rows"]),
    default="ridge",
    show_default=True,
    help=_METHOD_HELP,
)


@click.group()
def sensor() -> None:
    """The 3D rotary laser sensor: stripes, calibration, reconstruction, sphere fits."""


@sensor.command()
@click.argument("image", type=click.Path(dir_okay=False))
@option_table([
    (("--out", "out"), {"required": True, "type": click.Path(dir_okay=False),
        "help": "CENTERS.csv"}),
    _method_option,
    (("--sigma-px",), {"type": float, "default": None, "help": "Smoothing scale of the "
        "ridge detector [px] (default: 1.5, or the stripe's own Gaussian width when it "
        "is wider than 2.4 px)."}),
    (("--force",), {"is_flag": True, "help": "Overwrite OUT."}),
])  # fmt: skip
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
        if not 0.5 <= sigma_px <= 10.0:  # nan too
            raise click.BadParameter(
                f"expected a finite number within 0.5..10 px (the ridge detector's "
                f"sigma_px); got {sigma_px}",
                param_hint="--sigma-px",
            )
        if method != "ridge":
            raise click.BadParameter("only for --method ridge", param_hint="--sigma-px")
        options["sigma_px"] = sigma_px
    img = read_image(image)
    st = extract_stripes(img, **options)
    write_stripes(out, st, force=force)
    click.echo(f"{st.shape[0]} stripe centres -> {out}", err=True)


@sensor.command()
@click.argument("folder", type=click.Path(file_okay=False))
@option_table([
    (("--sensor", "sensor_file"), {"required": True, "type": click.Path(dir_okay=False)}),
    (("--out", "out"), {"required": True, "type": click.Path(dir_okay=False),
        "help": "CLOUD.csv"}),
    _method_option,
    jobs_option("Threads reading the images and extracting the stripes"),
    (("--force",), {"is_flag": True}),
])  # fmt: skip
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
    from kinecal.io import load_sensor, write_cloud
    from kinecal.sensor import Sensor
    from kinecal.workflows import reconstruct_scan

    prog = Progress(quiet)
    sen = load_sensor(sensor_file)
    assert isinstance(sen, Sensor)
    cloud = reconstruct_scan(
        folder, sen, method=method, jobs=jobs, source=sensor_file, progress=prog
    )
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
