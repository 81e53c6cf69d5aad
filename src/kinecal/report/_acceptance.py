"""The acceptance verdict of ``kinecal calibrate --accept RMS_MM[,MAX_MM]`` (issue 38).

The figure judged is the held-out one when cross-validation ran (the accuracy the user
will get on poses the fit did not see), else the error on the calibration data itself,
and the verdict says which."""

from __future__ import annotations

import math
from typing import Any

__all__ = ["acceptance", "parse_accept", "verdict_line"]


def parse_accept(text: str) -> tuple[float, float | None]:
    """``"RMS_MM"`` or ``"RMS_MM,MAX_MM"`` -> the limits [mm]; ValueError with what is
    expected when the text is not two positive finite numbers."""
    parts = [p.strip() for p in text.split(",")]
    if not 1 <= len(parts) <= 2:
        raise ValueError(f"expected RMS_MM or RMS_MM,MAX_MM; got {text!r}.")
    out: list[float] = []
    for p in parts:
        try:
            v = float(p)
        except ValueError:
            raise ValueError(
                f"expected RMS_MM or RMS_MM,MAX_MM (numbers in mm); got {text!r}."
            ) from None
        if not math.isfinite(v) or v <= 0:
            raise ValueError(f"limits must be positive finite mm; got {p!r}.")
        out.append(v)
    return out[0], (out[1] if len(out) == 2 else None)


def acceptance(
    rms_limit_mm: float,
    max_limit_mm: float | None,
    held_out: Any | None,
    after: Any,
) -> dict[str, Any]:
    """report.json's ``acceptance`` block.

    held_out : HeldOutAccuracy or None; its figure that imitates a new session (new
        session, new region, or the user's groups) is judged, its max the largest
        error over the held-out folds.
    after : Metrics of the calibrated model on the calibration data (judged without
        ``held_out``).
    """
    if held_out is not None:
        fig = held_out.transfer  # new session, new region or the user's groups
        rms = float(fig.model.rms_mm)
        mx = max((float(f.max_mm) for f in fig.model.folds), default=math.nan)
        judged = f"held-out ({fig.name}, {len(fig.folds.test)}-fold cross-validation)"
    else:
        rms, mx = float(after.rms_mm), float(after.max_mm)
        judged = "calibration data (no cross-validation ran)"
    pairs = [("rms_mm", rms, rms_limit_mm)]
    if max_limit_mm is not None:
        pairs.append(("max_mm", mx, max_limit_mm))
    checks: list[dict[str, Any]] = [
        {"figure": f, "value": v, "limit": lim, "pass": bool(v <= lim)}
        for f, v, lim in pairs
    ]
    return {
        "rms_limit_mm": rms_limit_mm,
        "max_limit_mm": max_limit_mm,
        "judged": judged,
        "rms_mm": rms,
        "max_mm": mx,
        "checks": checks,
        "pass": all(c["pass"] for c in checks),
    }


def verdict_line(acc: dict[str, Any]) -> str:
    """One console line: PASS/FAIL, the figures against their limits, what was judged."""
    parts = [
        f"{c['figure'].replace('_mm', '').upper()} {c['value']:.4f} mm "
        f"{'<=' if c['pass'] else '>'} {c['limit']:g} mm"
        for c in acc["checks"]
    ]
    return f"{'PASS' if acc['pass'] else 'FAIL'}  {', '.join(parts)}; judged: {acc['judged']}"
