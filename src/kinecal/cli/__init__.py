"""The ``kinecal`` command. Parsing only: every command loads files and calls the API.

Heavy modules (numpy, scipy, matplotlib, OpenCV) are imported inside the commands so
``kinecal --help`` starts fast. Exit codes: 0 success, 1 internal error, 2 bad input or
usage, 3 calibration failed (no convergence), 4 some targets unreachable.
"""

from __future__ import annotations

import sys

import click

from kinecal._version import __version__

EXIT_BAD_INPUT = 2
EXIT_NOT_CONVERGED = 3
EXIT_UNREACHABLE = 4


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="kinecal")
def cli() -> None:
    """kinecal: calibrate robots and robotic vision systems.

    Unified kinematic model plus joint compliance (Ye et al., Sensors 2024). Files use mm
    and degrees; see DESIGN §11 or each command's --help for the formats.
    """
    from kinecal import keep_freed_memory
    from kinecal._parallel import single_thread_blas

    keep_freed_memory()  # a command is one run: keep freed arrays for reuse
    single_thread_blas()  # small matrices; the cores go to worker processes instead


def _register() -> None:
    from kinecal.cli import (
        _calibrate,
        _compensate,
        _export,
        _fk,
        _plan,
        _report,
        _sensor,
        _simulate,
    )

    for cmd in (
        _fk.fk,
        _fk.robots,
        _fk.import_urdf,
        _calibrate.calibrate,
        _calibrate.evaluate,
        _compensate.compensate,
        _export.export_urdf,
        _simulate.simulate,
        _simulate.compare,
        _simulate.demo,
        _sensor.sensor,
        _plan.plan,
        _report.report,
    ):
        cli.add_command(cmd)


_register()


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``kinecal`` console script; returns the exit code."""
    from kinecal.errors import CalibError

    try:
        rv = cli.main(args=argv, prog_name="kinecal", standalone_mode=False)
    except click.exceptions.Exit as exc:
        return int(exc.exit_code)
    except click.ClickException as exc:
        exc.show()
        return int(exc.exit_code)
    except click.exceptions.Abort:
        click.echo("Aborted.", err=True)
        return 1
    except CalibError as exc:
        click.echo(f"kinecal: error: {exc}", err=True)
        return EXIT_BAD_INPUT
    except (
        FileExistsError,
        FileNotFoundError,
        IsADirectoryError,
        PermissionError,
    ) as exc:
        click.echo(f"kinecal: error: {exc}", err=True)
        return EXIT_BAD_INPUT
    return rv if isinstance(rv, int) else 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
