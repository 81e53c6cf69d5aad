"""Parameter tables of the calibration report (HTML): frames, joint geometry, compliance,
and every parameter with its change from nominal and its significance."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from kinecal.report._format import e, num, pm, ratio, table

__all__ = [
    "PRIOR_DOMINATED",
    "SIGNIFICANT",
    "compliance_table",
    "dh_table",
    "frames_table",
    "parameter_table",
]

# The rule of the identification's warning "determined mostly by their prior".
PRIOR_DOMINATED = 0.7
SIGNIFICANT = 3.0  # |change| / std from which a change from nominal is significant


def frames_table(cal: Any) -> str:
    m = cal.model
    L = m.layout
    rows = []
    for which, labels in (("base", m.spec.sets), ("cam", m.spec.markers)):
        E = m.frame_euler(cal.params, which)
        idx = m.base_index if which == "base" else m.cam_index
        for k, lab in enumerate(labels):
            name = ("T_user_base" if which == "base" else "T_flange_cam") + (
                f" [{lab}]" if lab else ""
            )
            cells = [e(name)]
            for c in range(6):
                v = E[k, c] * (1e3 if c < 3 else 180 / np.pi)
                i = idx[k, c] if c < idx.shape[1] else None
                sd = cal.std[i] * L.to_file[i] if i is not None else np.nan
                cells.append(pm(v, sd))
            rows.append(cells)
    return table(
        ["frame", "x [mm]", "y [mm]", "z [mm]", "r [deg]", "w [deg]", "p [deg]"], rows
    )


def dh_table(cal: Any) -> str:
    L = cal.model.layout
    n = cal.model.n_joints
    fields = [("theta_offset", "θ [deg]"), ("d", "d [mm]"), ("a", "a [mm]")]
    fields += [("alpha", "α [deg]"), ("beta", "β [deg]")]
    if not any(f"joint{j}.beta" in L for j in range(1, n + 1)):
        fields = fields[:4]
    rows = []
    for j in range(1, n + 1):
        cells = [f"J{j}"]
        for key, _ in fields:
            name = f"joint{j}.{key}"
            if name not in L:
                cells.append("—")
                continue
            i = L.index(name)
            tag = (
                ""
                if cal.status[i] == "estimated"
                else f" <span class=warn>({e(cal.status[i])})</span>"
            )
            cells.append(
                pm(cal.params[i] * L.to_file[i], cal.std[i] * L.to_file[i]) + tag
            )
        rows.append(cells)
    return table(["joint"] + [h for _, h in fields], rows)


def compliance_table(cal: Any) -> str:
    L = cal.model.layout
    rows = []
    payload = cal.reference_payload_kg
    for i, s in enumerate(L.specs):
        if s.group not in ("ntm", "load", "link"):
            continue
        if s.kind == "ntm":
            scale, unit = 1e3, "10⁻³ rad"
        elif s.kind == "compliance":
            scale, unit = 1e3, "10⁻³ rad/m (per unit weight)"
        else:
            scale, unit = L.to_file[i], s.unit.file_unit
        phys = ""
        if s.kind == "compliance" and payload:
            phys = pm(
                cal.params[i] / (payload * 9.80665), cal.std[i] / (payload * 9.80665)
            )
        rows.append(
            [
                e(s.name),
                pm(cal.params[i] * scale, cal.std[i] * scale),
                e(unit),
                phys,
                e(cal.status[i]),
            ]
        )
    if not rows:
        return "<p class=muted>This model has no compliance terms.</p>"
    return table(["parameter", "value ± std", "unit", "rad/(N·m)", "status"], rows)


def parameter_table(params: list[Mapping[str, Any]]) -> str:
    """Every parameter with its change from the start (nominal) and its significance."""
    rows, cls = [], []
    for p in params:
        v, s0, sd = p.get("value"), p.get("start"), p.get("std")
        est = p.get("status") == "estimated"
        d = (v - s0) if est and v is not None and s0 is not None else None
        z = abs(d) / sd if d is not None and sd else None
        prior = p.get("prior_std")
        share = sd / prior if sd and prior else None
        rows.append(
            [
                e(p["name"]),
                pm(v, sd),
                e(p.get("unit", "")),
                num(d),
                ratio(z),
                num(prior),
                num(share, 2)
                + (" (prior)" if share and share > PRIOR_DOMINATED else ""),
                e(p.get("status", "")),
            ]
        )
        cls.append("fixed" if not est else "sig" if z and z >= SIGNIFICANT else "")
    head = ["name", "value ± std", "unit", "change from nominal", "|change| / std"]
    head += ["prior std", "std / prior std", "status"]
    return table(head, rows, cls=cls)
