"""``kinecal report DIR``: (re)draw the HTML report of a calibration result folder."""

from __future__ import annotations

from typing import Any

import click

from kinecal.cli._common import Progress, common_options, option_table


@click.command()
@click.argument("folder", type=click.Path(file_okay=False), required=False)
@option_table([
    (("--compare", "compare"), {"nargs": 2, "type": click.Path(file_okay=False),
        "metavar": "OLD_DIR NEW_DIR", "help": "Compare two calibrations of one robot "
        "instead: parameters that moved beyond their combined uncertainty, each model's "
        "accuracy on the other's data (when the manifests' data files are still there); "
        "writes NEW_DIR/compare.html (or --out)."}),
    (("--out", "out_path"), {"type": click.Path(dir_okay=False), "help": "Write the "
        "report here instead of DIR/report.html."}),
    (("--force",), {"is_flag": True, "help": "Overwrite an existing report."}),
])  # fmt: skip
@common_options
def report(
    folder: str | None,
    compare: tuple[str, str] | None,
    out_path: str | None,
    force: bool,
    quiet: bool,
) -> None:
    """Draw report.html from a folder written by `kinecal calibrate`.

    Reads DIR/model.yaml, DIR/report.json and DIR/residuals.csv (per-pose errors; without
    it the report has no per-pose figures); needs nothing else (no matplotlib).
    """
    from kinecal.workflows._report import draw_report

    say = Progress(quiet)
    if compare:
        if folder is not None:
            raise click.UsageError("give either DIR or --compare OLD_DIR NEW_DIR.")
        _compare(*compare, out_path, force, say)
        return
    if folder is None:
        raise click.UsageError("missing DIR (a folder written by kinecal calibrate).")
    say("report", f"drawing from {folder}")
    click.echo(f"wrote     {draw_report(folder, out_path, force=force)}")


def _compare(old: str, new: str, out_path: str | None, force: bool, say: Any) -> None:
    from pathlib import Path

    from kinecal.io import atomic_write_text
    from kinecal.workflows._compare import compare_calibration_folders

    if Path(old).resolve() == Path(new).resolve():  # issue 35: a comparison of nothing
        raise click.UsageError("--compare: OLD_DIR and NEW_DIR are one folder.")
    target = Path(out_path) if out_path else Path(new) / "compare.html"
    if target.exists() and not force:
        raise FileExistsError(f"{target} exists; use --force to overwrite it.")
    say("compare", f"{old} against {new}")
    c = compare_calibration_folders(old, new)
    html, lines = c.html(), c.lines()  # before the file (issue 35)
    atomic_write_text(target, html, force=True)
    click.echo("\n".join([*lines, f"wrote     {target}"]))
