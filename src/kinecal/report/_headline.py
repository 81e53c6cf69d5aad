"""The figure a calibration summary leads with (issue 38): the held-out accuracy when
cross-validation ran, with the percentiles of the errors on the calibration data.

report.json's ``accuracy`` block; the console and report.html read it."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from kinecal.report._format import e, num

__all__ = ["accuracy_block", "accuracy_html", "accuracy_lines"]

_PCT = (50, 95, 99)


def _dist(err_mm: np.ndarray) -> dict[str, float]:
    """RMS, P50/P95/P99 and max of 3-D error vectors (N, 3) [mm]."""
    return _norm_dist(np.linalg.norm(np.asarray(err_mm, dtype=np.float64), axis=1))


def _norm_dist(d: np.ndarray) -> dict[str, float]:
    """RMS, P50/P95/P99 and max of error norms (N,) [mm]."""
    d = d[np.isfinite(d)]
    if d.size == 0:
        return {}
    out = {"rms_mm": float(np.sqrt(np.mean(d**2)))}
    out.update(_percentiles(d))
    out["max_mm"] = float(d.max())
    return out


def _percentiles(d: np.ndarray) -> dict[str, float]:
    from kinecal._stats import quantiles  # np.percentile would import numpy.ma

    return {
        f"p{p}_mm": float(v)
        for p, v in zip(_PCT, quantiles(d, [p / 100 for p in _PCT]), strict=True)
    }


def accuracy_block(errors: Any, held_out: Any | None) -> dict[str, Any]:
    """``accuracy``: which figure leads, the held-out RMS (± its standard error) and
    largest held-out error, and the distribution of the errors on the calibration data
    before and after.

    errors : PoseErrors of the calibration (before_mm, after_mm).
    held_out : HeldOutAccuracy or None (``--cv off``).
    """
    out: dict[str, Any] = {
        "leads": "held-out" if held_out is not None else "calibration data",
        "calibration_after": _dist(errors.after_mm),
        "calibration_before": _dist(errors.before_mm),
    }
    if held_out is not None:
        figs = []
        for fig in held_out.figures:
            fmax = [float(f.max_mm) for f in fig.model.folds]
            entry = {
                "name": fig.name,
                "folds": len(fig.folds.test),
                "unit": fig.folds.unit,
                "rms_mm": float(fig.model.rms_mm),
                "se_mm": float(fig.model.rms_se_mm),
                "max_mm": max(fmax) if fmax else math.nan,
                "nominal_rms_mm": float(fig.nominal.rms_mm),
            }
            norms = fig.model.norms_mm
            if norms is not None and np.isfinite(norms).any():
                entry.update(_percentiles(norms[np.isfinite(norms)]))
            figs.append(entry)
        out["held_out"] = figs
    return out


def accuracy_lines(block: dict[str, Any]) -> list[str]:
    """Console lines, the held-out figures first."""
    lines = []
    for f in block.get("held_out", []):
        pct = (
            f"P50 {f['p50_mm']:.4f}  P95 {f['p95_mm']:.4f}  P99 {f['p99_mm']:.4f}  "
            if "p50_mm" in f
            else ""
        )
        lines.append(
            f"held-out  RMS {f['rms_mm']:.4f} ± {f['se_mm']:.4f} mm  {pct}max "
            f"{f['max_mm']:.4f} mm  {f['name']} ({f['folds']}-fold CV by {f['unit']}; "
            f"nominal {f['nominal_rms_mm']:.4f} mm)"
        )
    a = block.get("calibration_after") or {}
    if a:
        lines.append(
            f"after     RMS {a['rms_mm']:.4f} mm  P50 {a['p50_mm']:.4f}  P95 "
            f"{a['p95_mm']:.4f}  P99 {a['p99_mm']:.4f}  max {a['max_mm']:.4f} mm  "
            "(calibration data)"
        )
    return lines


def accuracy_html(summary: dict[str, Any] | Any) -> str:
    """The first paragraph of the summary box: the figure the user will get."""
    block = summary.get("accuracy") if hasattr(summary, "get") else None
    if not block:
        return ""
    rows = []
    for f in block.get("held_out", []):
        rows.append(
            f"<tr><td class=l><b>held-out, {e(f['name'])}</b> ({e(f['folds'])}-fold "
            f"cross-validation by {e(f['unit'])})</td><td><b>{num(f['rms_mm'])}</b> ± "
            f"{num(f['se_mm'], 2)}</td>"
            + "".join(f"<td>{num(f.get(f'p{p}_mm'))}</td>" for p in _PCT)
            + f"<td>{num(f['max_mm'])}</td></tr>"
        )
    for key, label in (
        ("calibration_after", "calibration data, after"),
        ("calibration_before", "calibration data, before"),
    ):
        d = block.get(key) or {}
        if d:
            rows.append(
                f"<tr><td class=l>{label}</td><td>{num(d['rms_mm'])}</td>"
                + "".join(f"<td>{num(d[f'p{p}_mm'])}</td>" for p in _PCT)
                + f"<td>{num(d['max_mm'])}</td></tr>"
            )
    lead = (
        "Expected accuracy on new poses (held-out, cross-validated)"
        if block.get("leads") == "held-out"
        else "Errors on the calibration data (cross-validation off: no held-out figure)"
    )
    return (
        f"<h3 id=accuracy>{lead}</h3><table><tr><th class=l>errors [mm]</th>"
        "<th>RMS</th><th>P50</th><th>P95</th><th>P99</th><th>max</th></tr>"
        + "".join(rows)
        + "</table><p class=muted>3-D position errors. Held-out: each fold's poses "
        "predicted by the model fitted without them; its percentiles and max are over "
        "the held-out errors of every pose of every fold.</p>"
    )
