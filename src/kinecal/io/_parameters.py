"""The one serialisation of a calibrated model's parameters (file units).

``model.yaml`` (``parameters``), ``report.json`` (``parameters``) and the HTML report's
tables are all written from :func:`parameter_records`, so a parameter reads the same
everywhere: the same name, unit, value, standard deviation and status.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from kinecal.measurement import CalibratedModel
from kinecal.typing import Float

__all__ = ["parameter_records"]


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(float(x)) else None


_JOINT_GROUPS = ("joint", "ntm", "load", "link")


def parameter_records(
    cal: CalibratedModel,
    *,
    start: Float | None = None,
    prior_sigma: Float | None = None,
) -> list[dict[str, Any]]:
    """Every parameter of ``cal``, in layout order, in file units (mm, deg, ...).

    Parameters
    ----------
    cal : the calibrated model.
    start : (P,) SI, optional: the value before calibration (``start``: nominal
        geometry with fitted frames).
    prior_sigma : (P,) SI, optional: the prior standard deviations (``prior_std``;
        None where a parameter has no prior).

    Returns
    -------
    list of dict
        ``name, group, joint, field, label, unit, value, std, status`` (``std`` None
        where not estimated), ``joint_name`` (the robot's name of the parameter's joint,
        or of the joint a link body moves with, where it is not the default ``J<k>``),
        and ``start`` / ``prior_std`` when given.
    """
    layout = cal.model.layout
    names = cal.model.robot.joint_names
    out = []
    for i, ps in enumerate(layout.specs):
        f = ps.unit.to_file
        rec: dict[str, Any] = {
            "name": ps.name,
            "group": ps.group,
            "joint": ps.joint,
            "field": ps.field,
            "label": ps.label,
            "unit": ps.unit.file_unit,
            "value": float(cal.params[i] * f),
            "std": _finite(cal.std[i] * f),
            "status": cal.status[i],
        }
        if ps.joint is not None and ps.group in _JOINT_GROUPS:
            # The robot's own name of the joint (of the joint a link body moves with).
            if names[ps.joint - 1] != f"J{ps.joint}":
                rec["joint_name"] = names[ps.joint - 1]
        if start is not None:
            rec["start"] = float(start[i] * f)
        if prior_sigma is not None:
            rec["prior_std"] = _finite(prior_sigma[i] * f)
        out.append(rec)
    return out


def records_by_name(records: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The records keyed by parameter name."""
    return {r["name"]: r for r in records}


def record_value(rec: dict[str, Any]) -> tuple[float, float]:
    """``(value, std)`` of a record, std NaN where not estimated."""
    sd = rec["std"]
    return rec["value"], np.nan if sd is None else sd
