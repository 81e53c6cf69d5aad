"""Plain-data summaries of calibrations and comparisons (for report.json and the CLI)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from kinecal._stats import median
from kinecal._version import __version__

if TYPE_CHECKING:  # annotations only: a calibration's summary needs no cross-validation
    from kinecal.identification import CalibrationResult, ComparisonRow
    from kinecal.measurement import Metrics

__all__ = ["calibration_summary", "comparison_table", "format_table", "parameter_table"]


def parameter_table(result: CalibrationResult) -> list[dict[str, Any]]:
    """Every parameter: name, group, joint, field, label, unit, value, std, start value,
    status and the std of its prior (None without one), in file units: the records of
    :func:`kinecal.io.parameter_records` (the same as model.yaml's)."""
    from kinecal.io import parameter_records

    L = result.calibrated.model.layout
    prior = result.prior.sigma if result.prior is not None else np.full(L.size, np.inf)
    return parameter_records(
        result.calibrated, start=result.registered, prior_sigma=prior
    )


def _metrics(m: Metrics) -> dict[str, Any]:
    return m.as_dict()


def _noise(result: CalibrationResult) -> dict[str, Any]:
    """The noise the calibration weighed the data with (sigmas per component kind; the
    median over the rows where they differ per set or marker) and, for pose data whose
    orientations were weighed otherwise, their estimated noise."""
    w = result.weights
    out: dict[str, Any] = {"sigma_mm": float(median(w.sigma)) * 1e3}
    if w.sigma_rot is not None:
        out["sigma_deg"] = float(np.degrees(median(w.sigma_rot)))
    est = next((d for d in result.diagnostics if d.code == "noise_model"), None)
    if est is not None:
        out["estimate"] = est.message
    return out


def calibration_summary(
    result: CalibrationResult, *, extra: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The content of ``report.json``.

    Besides the metrics, stages, identifiability and parameters, it holds what the
    report's figures need beyond ``model.yaml`` and ``residuals.csv``: the correlation
    matrix of the estimated parameters (``correlation``: names and matrix, 4 decimals)
    and the singular values of the scaled Jacobian (``identifiability.singular_values``).
    """
    ident = result.identifiability
    corr = result.correlation()
    names = result.calibrated.model.layout.names
    free = np.flatnonzero(ident.free)
    a, b = np.triu_indices(free.size, 1)  # every pair once, in the order of a loop
    pairs = corr[free[a], free[b]]
    strong = [
        {"a": names[free[a[k]]], "b": names[free[b[k]]], "correlation": float(pairs[k])}
        for k in np.flatnonzero(np.abs(pairs) > 0.95).tolist()
    ]
    strong.sort(key=lambda d: -abs(d["correlation"]))
    return {
        "kinecal_version": __version__,
        "model": result.calibrated.model.spec.name,
        "robot": result.calibrated.model.robot.name,
        "data": dict(result.calibrated.info),
        "success": result.success,
        "seconds": result.seconds,
        "before": _metrics(result.metrics_before),
        "after": _metrics(result.metrics_after),
        "sigma0": result.sigma0,
        "noise_sigma_mm": median(result.weights.sigma) * 1e3,
        "prior_scale_by_evidence": dict(result.prior_factors),
        "identifiability": {
            "estimated": ident.rank,
            "parameters": int(ident.candidate.sum()),
            "condition_number": ident.condition_number,
            "unidentifiable": [
                {
                    "name": d.name,
                    "explained_by": [
                        {"name": n, "coefficient": c} for n, c in d.partners
                    ],
                }
                for d in ident.dropped
            ],
            "poorly_determined": [{"name": n, "fraction": f} for n, f in ident.weak],
            "strong_correlations": strong,
            "summary": ident.summary(),
            "singular_values": [float(v) for v in ident.singular_values],
        },
        "stages": [
            {
                "name": s.name,
                "parameters": s.n_free,
                "rms_before_mm": s.rms_before_mm,
                "rms_after_mm": s.rms_after_mm,
                "iterations": s.iterations,
                "status": s.status,
                "converged": s.success,
                "seconds": s.seconds,
                "log": s.iteration_log,
            }
            for s in result.stages
        ],
        "outliers": [
            {"row": o.row, "error_mm": o.error_mm, "z": o.z} for o in result.outliers
        ],
        "rejected_rows": [
            {"row": o.row, "error_mm": o.error_mm, "z": o.z} for o in result.rejected
        ],
        "noise": _noise(result),
        "warnings": list(result.warnings),
        "diagnostics": [d.as_dict() for d in result.diagnostics],
        "parameters": parameter_table(result),
        "correlation": {
            "names": [names[i] for i in free],
            "matrix": np.round(corr[np.ix_(free, free)], 4).tolist(),
        },
        **(extra or {}),
    }


def comparison_table(rows: list[ComparisonRow]) -> list[dict[str, Any]]:
    """Rows of a Table 5/8-style comparison (held-out metrics, mm)."""
    return [
        {
            "model": r.model,
            "size": r.size,
            "estimated": r.n_free,
            "rms_mm": r.test.rms_mm,
            "std_mm": r.test.std_mm,
            "mean_mm": r.test.mean_mm,
            "max_mm": r.test.max_mm,
            "train_rms_mm": r.train.rms_mm,
            "n_test": r.test.n,
            "seconds": r.seconds,
        }
        for r in rows
    ]


def format_table(rows: list[dict[str, Any]], title: str = "") -> str:
    """A text table like the paper's Tables 5 and 8 (values in mm)."""
    head = f"{'Method':<10} {'Size':>4} {'Est.':>4} {'RMS':>9} {'Std.':>9} {'Avg':>9} {'Max':>9}"
    lines = ([title] if title else []) + [head, "-" * len(head)]
    for r in rows:
        lines.append(
            f"{r['model']:<10} {r['size']:>4} {r['estimated']:>4} {r['rms_mm']:>9.4f} "
            f"{r['std_mm']:>9.4f} {r['mean_mm']:>9.4f} {r['max_mm']:>9.4f}"
        )
    lines.append(
        f"(held-out errors in mm over {rows[-1]['n_test']} poses)" if rows else ""
    )
    return "\n".join(lines)
