"""``kinecal report DIR``: (re)draw the HTML report of a calibration result folder."""

from __future__ import annotations

import click

from kinecal.cli._common import Progress, common_options


@click.command()
@click.argument("folder", type=click.Path(file_okay=False))
@click.option(
    "--out",
    "out_path",
    type=click.Path(dir_okay=False),
    help="Write the report here instead of DIR/report.html.",
)
@click.option("--force", is_flag=True, help="Overwrite an existing report.")
@common_options
def report(folder: str, out_path: str | None, force: bool, quiet: bool) -> None:
    """Draw report.html from a folder written by `kinecal calibrate`.

    Reads DIR/model.yaml, DIR/report.json and DIR/residuals.csv (per-pose errors; without
    it the report has no per-pose figures); needs nothing else (no matplotlib).
    """
    from pathlib import Path

    from kinecal.errors import CalibError, DataError
    from kinecal.report import write_report

    say = Progress(quiet)
    d = Path(folder)
    if not d.is_dir():
        raise DataError(
            f"{d}: no such folder; expected a folder written by kinecal calibrate."
        )
    say("report", f"drawing from {folder}")
    try:
        path = write_report(folder, out=out_path, force=force)
    except CalibError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        # report.json was edited or damaged: its values are not what calibrate writes
        # (model.yaml and residuals.csv are validated by their readers).
        raise DataError(
            f"{d / 'report.json'}: unexpected content ({type(exc).__name__}: {exc}); "
            "expected the report.json kinecal calibrate wrote (restore it, or run "
            "calibrate again)."
        ) from exc
    click.echo(f"wrote     {path}")
