"""The report workflow of ``kinecal report DIR``: report.html drawn again from the files
of a calibration's result folder."""

from __future__ import annotations

from pathlib import Path

from kinecal.errors import CalibError, DataError

__all__ = ["draw_report", "note_folder_inputs"]

# The files of a calibration's folder that ``kinecal report`` reads.
FOLDER_INPUTS = ("model.yaml", "report.json", "residuals.csv", "manifest.json")


def draw_report(
    folder: str | Path, out: str | Path | None = None, *, force: bool = False
) -> Path:
    """Draw report.html (or ``out``) from ``folder``, written by ``kinecal calibrate``
    (model.yaml, report.json, residuals.csv); the file written.

    Raises
    ------
    DataError
        No such folder, or a report.json that is not what calibrate writes (edited or
        damaged; model.yaml and residuals.csv are validated by their readers).
    """
    from kinecal.report import write_report

    d = Path(folder)
    if not d.is_dir():
        raise DataError(
            f"{d}: no such folder; expected a folder written by kinecal calibrate."
        )
    note_folder_inputs(d)
    try:
        return write_report(folder, out=out, force=force)
    except CalibError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as exc:
        raise DataError(
            f"{d / 'report.json'}: unexpected content ({type(exc).__name__}: {exc}); "
            "expected the report.json kinecal calibrate wrote (restore it, or run "
            "calibrate again)."
        ) from exc


def note_folder_inputs(folder: Path) -> None:
    """The files of a calibration ``folder`` a report reads are inputs of the command:
    no output of it may replace them (``report DIR --out DIR/report.json``)."""
    from kinecal._outputs import note_input

    for name in FOLDER_INPUTS:
        note_input(folder / name, f"the {name} of {folder}")
