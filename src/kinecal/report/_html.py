"""The HTML report of a model comparison (Tables 5, 8; Figures 11, 15), self-contained:
inline SVG figures, readable offline. The calibration report is in :mod:`._calibration`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kinecal.identification import ComparisonRow
from kinecal.measurement import Measurements
from kinecal.report import _figures as F
from kinecal.report._format import e, figure, num, page, table
from kinecal.typing import Float

__all__ = ["write_comparison_report"]


def write_comparison_report(
    path: str | Path,
    rows: list[ComparisonRow],
    test: Measurements,
    *,
    title: str,
    notes: list[str] | None = None,
    extra_html: str = "",
    figure_dir: str | Path | None = None,
) -> Path:
    """Report of a model comparison on held-out data (Tables 5, 8 and Figures 11, 15).

    ``figure_dir``: also write each figure there as an SVG file (for slides and READMEs).
    """
    from kinecal.io import atomic_write_text

    body = _summary(rows, notes)
    body.append(extra_html)
    body.append("<h2>Figures (as Figures 11 and 15)</h2>")
    svgs = _figures(rows, test)
    body += [figure(svg, caption) for svg, caption in svgs.values()]
    if figure_dir is not None:
        for name, (svg, _) in svgs.items():
            atomic_write_text(Path(figure_dir) / f"{name}.svg", svg + "\n", force=True)
    return atomic_write_text(path, page(title, "\n".join(body)), force=True)


def _summary(rows: list[ComparisonRow], notes: list[str] | None) -> list[str]:
    """The opening box (the held-out RMS of the first and the last model, the notes)
    and the comparison table."""
    from kinecal.report._summary import comparison_table

    tab = comparison_table(rows)
    body = ["<div class=box>"]
    if len(rows) >= 2:
        first, last = rows[0], rows[-1]
        body.append(
            f"<p>Held-out RMS error: <b>{e(first.model)} {num(first.test.rms_mm)} mm → "
            f"{e(last.model)} {num(last.test.rms_mm)} mm</b> over {last.test.n} poses not "
            "used for calibration.</p>"
        )
    body += [f"<p>{e(n)}</p>" for n in notes or []]
    body.append("</div><h2>Comparison (Tables 5, 8)</h2>")
    head = ["method", "model size", "estimated", "RMS [mm]", "Std [mm]", "Avg [mm]"]
    head += ["Max [mm]", "train RMS [mm]"]
    body.append(
        table(
            head,
            [
                [e(r["model"]), str(r["size"]), str(r["estimated"])]
                + [num(r[k]) for k in ("rms_mm", "std_mm", "mean_mm", "max_mm")]
                + [num(r["train_rms_mm"])]
                for r in tab
            ],
        )
    )
    return body


def _figures(
    rows: list[ComparisonRow], test: Measurements
) -> dict[str, tuple[str, str]]:
    """The figures of the held-out errors: name -> (SVG, caption), in the report's
    order."""
    errs: dict[str, Float] = {}
    xyz: dict[str, Float] = {}
    for r in rows:
        if r.calibrated is None:
            continue
        blk = r.calibrated.predict(test)
        errs[r.model] = np.linalg.norm(blk.raw_position, axis=1) * 1e3
        xyz[r.model] = blk.raw_position * 1e3
    out: dict[str, tuple[str, str]] = {}
    names = list(errs)
    methods = {k: v for k, v in errs.items() if k != "nominal"}
    if len(names) >= 2:
        svg = F.fig_errors_before_after(
            errs[names[0]],
            errs[names[-1]],
            f"(a) position errors: {names[0]} vs {names[-1]}",
            (names[0], names[-1]),
        )
        out["a_errors_before_after"] = (svg, "Held-out position error per point [mm].")
    if methods:
        out["b_histogram"] = (
            F.fig_error_histogram(methods),
            "Histogram of held-out errors per method.",
        )
        out["c_axis_counts"] = (
            F.fig_axis_counts({k: v for k, v in xyz.items() if k != "nominal"}),
            "Counts of held-out errors along x, y, z per method.",
        )
        out["d_violin"] = (
            F.fig_violin(methods),
            "Distributions of held-out errors per method.",
        )
    if names:
        out["workspace"] = (
            F.fig_workspace(test.reference_points() * 1e3, errs[names[-1]]),
            f"Held-out errors of {names[-1]} over the workspace [mm].",
        )
    return out
