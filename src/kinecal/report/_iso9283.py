"""The ISO 9283 section of a report: pose accuracy AP and repeatability RP per test
point, distance accuracy AD and repeatability RD, before (nominal robot) and after
(calibrated model) compensation, from the ``iso9283`` block of report.json
(:meth:`kinecal.iso9283.IsoEvaluation.as_dict`). Definitions: docs/iso9283.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from kinecal.report._format import e, figure, num, page, table
from kinecal.report._svg import COLORS, Figure

__all__ = ["fig_iso9283", "iso9283_section", "render_iso9283_report"]

_W = 760.0
_L, _R, _T, _B = 72.0, 16.0, 30.0, 46.0
_NAMES = {"nominal": "nominal robot (before)", "model": "calibrated model (after)"}


def fig_iso9283(block: Mapping[str, Any]) -> str:
    """Bars per test point: AP_P before and after, and RP_l [mm]."""
    series: list[tuple[str, list[float]]] = []
    for key in ("nominal", "model"):
        fig = block.get(key)
        if fig:
            series.append((f"AP {_NAMES[key]}", [p["ap_mm"] for p in fig["points"]]))
    model = block["model"]
    series.append(("RP (both)", [p["rp_mm"] for p in model["points"]]))
    labels = [p["point"] for p in model["points"]]
    vals = np.array([v for _, v in series], float)
    # headroom above the bars for the legend
    top = float(np.nanmax(vals)) * 1.5 if np.isfinite(vals).any() else 1.0
    f = Figure(_W, 300)
    k_pts = len(labels)
    p = f.panel(
        _L,
        _T,
        _W - _L - _R - 200,
        300 - _T - _B,
        (-0.5, k_pts - 0.5),
        (0.0, top or 1.0),
        xlabel="ISO 9283 test point",
        ylabel="[mm]",
        title="Pose accuracy AP and repeatability RP per point",
        xticks=[(float(i), lab) for i, lab in enumerate(labels)],
    )
    width = 0.8 / len(series)
    for k, (_, v) in enumerate(series):
        x0 = np.arange(k_pts) - 0.4 + k * width
        p.bars(x0, x0 + 0.9 * width, np.zeros(k_pts), v, COLORS[k % len(COLORS)])
    p.legend([(n, COLORS[k % len(COLORS)]) for k, (n, _) in enumerate(series)])
    return f.svg()


def _point_rows(fig: Mapping[str, Any], orient: bool) -> list[list[str]]:
    rows = []
    for p in fig["points"]:
        r = [e(p["point"]), str(p["n"]), num(p["ap_mm"])]
        r += [num(p[f"ap_{a}_mm"]) for a in "xyz"]
        r += [num(p["l_bar_mm"]), num(p["s_l_mm"]), num(p["rp_mm"])]
        if orient:
            r += [num(p.get(f"ap_{a}_deg")) for a in "abc"]
            r += [num(p.get(f"rp_{a}_deg")) for a in "abc"]
        rows.append(r)
    return rows


def _distance(fig: Mapping[str, Any], orient: bool) -> list[str]:
    d = fig.get("distance")
    if not d:
        return []
    row = [
        f"{e(d['pair'][0])}–{e(d['pair'][1])}",
        str(d["n"]),
        num(d["command_mm"], 7),
        num(d["mean_mm"], 7),
        num(d["ad_mm"]),
        *(num(d[f"ad_{a}_mm"]) for a in "xyz"),
        num(d["rd_mm"]),
    ]
    if orient:
        row += [num(d.get(f"ad_{a}_deg")) for a in "abc"]
        row += [num(d.get(f"rd_{a}_deg")) for a in "abc"]
    return row


def iso9283_section(block: Mapping[str, Any]) -> str:
    """HTML of the ISO 9283 results (``block``: report.json's ``iso9283``)."""
    model, nominal = block["model"], block.get("nominal")
    orient = block.get("kind") == "pose"
    out = ["<h2 id=iso9283>ISO 9283 pose accuracy and repeatability</h2>"]
    head = "<div class=box><p>"
    if nominal:
        head += (
            f"Worst pose accuracy AP over P1–P5: <b>{num(nominal['max_ap_mm'])} mm "
            f"before → {num(model['max_ap_mm'])} mm after</b> compensation; "
        )
    else:
        head += f"Worst pose accuracy AP: <b>{num(model['max_ap_mm'])} mm</b>; "
    head += (
        f"worst repeatability RP: <b>{num(model['max_rp_mm'])} mm</b> "
        "(compensation does not change it).</p>"
    )
    cyc = block.get("cycles", {})
    head += (
        f"<p class=muted>{e(block.get('standard', 'ISO 9283'))}; cycles per point: "
        + e(", ".join(f"{k} {v}" for k, v in cyc.items()))
        + f"; frame: {e(block.get('frame', ''))}"
        + (
            f"; refitted on these data: {e(', '.join(block['refit']))}"
            if block.get("refit")
            else ""
        )
        + ". AP is the distance from the command position to the mean attained "
        "position; RP = l̄ + 3 S_l is the radius of the sphere around that mean that "
        "holds the attained positions. Neither is an RMS error (docs/iso9283.md).</p>"
    )
    for note in block.get("notes", []):
        head += f"<p class=warn>{e(note)}</p>"
    out.append(head + "</div>")
    out.append(
        figure(
            fig_iso9283(block),
            "AP per test point before and after compensation, and RP [mm].",
        )
    )
    cols = ["point", "cycles", "AP_P [mm]", "AP_x [mm]", "AP_y [mm]", "AP_z [mm]"]
    cols += ["l̄ [mm]", "S_l [mm]", "RP_l [mm]"]
    if orient:
        cols += ["AP_a [deg]", "AP_b [deg]", "AP_c [deg]"]
        cols += ["RP_a ± [deg]", "RP_b ± [deg]", "RP_c ± [deg]"]
    for key in ("nominal", "model"):
        fig = block.get(key)
        if not fig:
            continue
        out.append(f"<h3>{e(_NAMES[key].capitalize())}</h3>")
        out.append(table(cols, _point_rows(fig, orient)))
        out.append(
            f"<p class=muted>RMS of the position errors of all rows, for comparison: "
            f"{num(fig['rms_mm'])} mm.</p>"
        )
    dist = [
        (k, _distance(block[k], orient)) for k in ("nominal", "model") if block.get(k)
    ]
    dist = [(k, r) for k, r in dist if r]
    if dist:
        out.append("<h3>Distance accuracy and repeatability (P2–P4)</h3>")
        dcols: Sequence[str] = [
            "model",
            "pair",
            "cycles",
            "D_c [mm]",
            "D̄ [mm]",
            "AD_P [mm]",
            "AD_x [mm]",
            "AD_y [mm]",
            "AD_z [mm]",
            "RD ± [mm]",
        ]
        if orient:
            dcols = [*dcols, "AD_a [deg]", "AD_b [deg]", "AD_c [deg]"]
            dcols = [*dcols, "RD_a ± [deg]", "RD_b ± [deg]", "RD_c ± [deg]"]
        out.append(table(dcols, [[e(_NAMES[k]), *r] for k, r in dist]))
    return "\n".join(out)


def render_iso9283_report(block: Mapping[str, Any], *, title: str) -> str:
    """A self-contained HTML page of the ISO 9283 results."""
    return page(title, iso9283_section(block))
