"""Helpers shared by the commands: progress display, option parsing, manifests."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

MODEL_CHOICES = ("kinematic", "ntm", "rfcm", "full", "auto")

# Options several commands share, declared once.
model_file_option = click.option(
    "--model",
    "model_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="A model.yaml written by `kinecal calibrate`.",
)
targets_option = click.option(
    "--targets",
    type=click.Path(dir_okay=False),
    help="Targets file (target, x_mm, y_mm, z_mm) for sensor data.",
)
allow_out_of_limits_option = click.option(
    "--allow-out-of-limits",
    is_flag=True,
    help="Accept joint values more than 1 deg (1 mm) beyond the robot's limits, with a "
    "warning, instead of refusing the file.",
)


def echo_diagnostics(found: Any) -> None:
    """Print the warnings among ``Diagnostic`` records on stderr."""
    for d in found:
        if d.severity == "warning":
            click.echo(f"warning   {d.message}", err=True)


def read_data_checked(
    data: str, robot: Any, targets: str | None, allow_out_of_limits: bool
) -> Any:
    """Read a measurement file and print the findings of its checks: (meas, findings)."""
    from kinecal.io import read_data

    meas, found = read_data(
        data, robot, targets, allow_out_of_limits=allow_out_of_limits
    )
    echo_diagnostics(found)
    return meas, found


def jobs_option(what: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--jobs N``: how many workers (``what``: "Worker processes for ...") share the
    command's work; 0 means one per CPU. Results never depend on it."""
    return click.option(
        "--jobs",
        type=click.IntRange(min=0),
        default=0,
        show_default=True,
        help=f"{what} (0: one per CPU; 1: serial). The result does not depend on it.",
    )


class Progress:
    """Stage-by-stage progress on stderr, silenced by ``--quiet``."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def __call__(self, stage: str, detail: str = "") -> None:
        if self.quiet:
            return
        dt = time.perf_counter() - self.t0
        click.echo(
            f"[{dt:6.2f}s] {stage}" + (f": {detail}" if detail else ""), err=True
        )


def parse_int_list(text: str | None, name: str) -> tuple[int, ...] | None:
    """``"1,2,3"`` -> (1, 2, 3); None stays None."""
    if text is None:
        return None
    try:
        return tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise click.BadParameter(
            f"expected comma-separated joint numbers; got {text!r}", param_hint=name
        ) from None


def manifest(inputs: dict[str, str | None], config: dict[str, Any]) -> dict[str, Any]:
    """Run manifest: version, command line, resolved config, input file hashes."""
    from kinecal._version import __version__
    from kinecal.io import file_sha256

    files = {}
    for key, path in inputs.items():
        if path and Path(path).is_file():
            files[key] = {"path": str(path), "sha256": file_sha256(path)}
    return {
        "kinecal_version": __version__,
        "command": " ".join(["kinecal", *sys.argv[1:]]),
        "python": sys.version.split()[0],
        "config": config,
        "inputs": files,
        "created_unix": time.time(),
    }


def common_options(f: Callable[..., Any]) -> Callable[..., Any]:
    f = click.option("--quiet", "-q", is_flag=True, help="No progress display.")(f)
    return f
