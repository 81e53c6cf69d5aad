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
    "name_cell",
    "parameter_table",
]

# The rule of the identification's warning "determined mostly by their prior".
PRIOR_DOMINATED = 0.7
SIGNIFICANT = 3.0  # |change| / std from which a change from nominal is significant


def _records(cal: Any) -> dict[str, dict[str, Any]]:
    """The model's parameters as model.yaml and report.json write them, by name."""
    from kinecal.io import parameter_records

    return {r["name"]: r for r in parameter_records(cal)}


def name_cell(rec: Mapping[str, Any]) -> str:
    """A parameter's name (as model.yaml keys it) and, where the robot names the
    parameter's joint (``joint_name``), that name beside it (display only)."""
    jn = rec.get("joint_name")
    return e(rec["name"]) + (f" <small class=muted>{e(jn)}</small>" if jn else "")


def _pm(rec: Mapping[str, Any]) -> str:
    return pm(rec["value"], np.nan if rec["std"] is None else rec["std"])


def frames_table(cal: Any) -> str:
    """The user and tool frames (with any reference rotation composed in); their std
    from the parameter records."""
    m = cal.model
    recs = list(_records(cal).values())
    rows = []
    for which, labels in (("base", m.spec.sets), ("cam", m.spec.markers)):
        E = m.frame_euler(cal.params, which)
        for k, lab in enumerate(labels):
            name = ("T_user_base" if which == "base" else "T_flange_cam") + (
                f" [{lab}]" if lab else ""
            )
            std = {
                r["field"]: r["std"]
                for r in recs
                if r["group"] == which and r["label"] == lab
            }
            cells = [e(name)]
            for c, key in enumerate("xyzrwp"):
                v = E[k, c] * (1e3 if c < 3 else 180 / np.pi)
                sd = std.get(key)
                cells.append(pm(v, np.nan if sd is None else sd))
            rows.append(cells)
    return table(
        ["frame", "x [mm]", "y [mm]", "z [mm]", "r [deg]", "w [deg]", "p [deg]"], rows
    )


def dh_table(cal: Any) -> str:
    recs = [r for r in _records(cal).values() if r["group"] == "joint"]
    n = cal.model.n_joints
    fields = [("theta_offset", "θ [deg]"), ("d", "d [mm]"), ("a", "a [mm]")]
    fields += [("alpha", "α [deg]"), ("beta", "β [deg]")]
    if not any(r["field"] == "beta" for r in recs):
        fields = fields[:4]
    by_key = {(r["joint"], r["field"]): r for r in recs}
    names = cal.model.robot.joint_names
    rows = []
    for j in range(1, n + 1):
        own = names[j - 1] != f"J{j}"  # the robot's name of the joint, where it has one
        cells = [f"J{j}" + (f" <small class=muted>{e(names[j - 1])}</small>" * own)]
        for key, _ in fields:
            rec = by_key.get((j, key))
            if rec is None:
                cells.append("—")
                continue
            tag = (
                ""
                if rec["status"] == "estimated"
                else f" <span class=warn>({e(rec['status'])})</span>"
            )
            cells.append(_pm(rec) + tag)
        rows.append(cells)
    return table(["joint"] + [h for _, h in fields], rows)


def _payload_weight(cal: Any) -> tuple[float | None, str]:
    """The weight [N] that is the unit of lambda* and where it comes from: the data's
    reference payload, else the robot's stated payload (its gravity model); None if
    neither is known."""
    kg = cal.reference_payload_kg
    if kg:
        return kg * G, "the data's reference payload"
    robot = getattr(cal.model, "robot", None)
    kg = getattr(robot, "payload_kg", None)
    if kg:
        return kg * G, "the robot's stated payload"
    return None, ""


G = 9.80665  # standard gravity [m/s^2]


def compliance_table(cal: Any) -> str:
    """Compliance terms; lambda* (per unit weight) also as compliance in rad/(N·m) and
    stiffness in N·m/rad where the unit weight is known. Columns that no row fills are
    left out."""
    rows = []
    w, source = _payload_weight(cal)
    any_phys = False
    for rec in _records(cal).values():
        if rec["group"] not in ("ntm", "load", "link"):
            continue
        comp = stiff = "—"
        if rec["group"] == "load" and w:
            # lambda* [rad/m] / weight [N] = compliance [rad/(N·m)]
            v, sd = rec["value"] / w, rec["std"]
            sd = np.nan if sd is None else sd / w
            comp = pm(v, sd)
            # stiffness 1/c, its std by first-order propagation sd / c^2
            stiff = pm(1.0 / v, sd / v**2) if v > 0 else "—"
            any_phys = True
        unit = rec["unit"] + (" (per unit weight)" if rec["group"] == "load" else "")
        rows.append([name_cell(rec), _pm(rec), e(unit), comp, stiff, e(rec["status"])])
    if not rows:
        return "<p class=muted>This model has no compliance terms.</p>"
    head = ["parameter", "value ± std", "unit"]
    if any_phys:
        head += ["compliance [rad/(N·m)]", "stiffness [N·m/rad]"]
    else:
        rows = [r[:3] + r[5:] for r in rows]
    note = (
        f"<p class=muted>Compliance = λ* / weight, with the weight of {e(source)} "
        f"({num(w, 2)} N); stiffness = 1 / compliance.</p>"
        if any_phys
        else ""
    )
    return table([*head, "status"], rows) + note


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
                name_cell(p),
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
