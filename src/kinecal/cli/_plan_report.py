"""What ``kinecal plan`` prints: the summary of its report.json (file units: mm, deg)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

__all__ = ["echo_summary"]


def echo_summary(
    doc: dict[str, Any],
    out: Path,
    rep: Path,
    as_json: bool,
    extra: list[str] | None = None,
) -> None:
    """Print the plan's summary (text or JSON); ``extra``: further files written."""
    if as_json:
        click.echo(
            json.dumps(
                {
                    k: doc[k]
                    for k in ("n_poses", "predicted", "random", "selection", "order")
                }
                | {"out": str(out), "report": str(rep)}
            )
        )
        return
    d, pr, rd = doc["design"], doc["predicted"], doc["random"]
    click.echo(f"candidates {doc['candidates']['n']} ({doc['candidates']['source']})")
    click.echo(
        f"model      {doc['model']}: {d['parameters']} parameters in the design"
        + (
            f"; not determined by any candidate: {', '.join(d['not_determined'])}"
            if d["not_determined"]
            else ""
        )
    )
    s = doc["selection"]
    click.echo(
        f"plan       {doc['n_poses']} poses, {doc['criterion']}-optimal (greedy + "
        f"{doc['exchange']}: {s['swaps']} swaps, {s['seconds']:.2f} s)"
    )
    if doc.get("before"):
        b = doc["before"]
        click.echo(
            f"before     held-out RMS {b['heldout_rms_mm']:.4f} mm = {b['ratio']:.3f}x "
            "the noise floor"
        )
    click.echo(
        f"predicted  held-out RMS {pr['heldout_rms_mm']:.4f} mm = {pr['ratio']:.3f}x the "
        f"noise floor {pr['floor_mm']:.4f} mm"
    )
    click.echo(
        f"random     held-out RMS {rd['heldout_rms_mm_mean']:.4f} mm = {rd['ratio']:.3f}x "
        f"(mean of {rd['draws']} random plans of {doc['n_poses']})"
    )
    ratios = [
        (p["std_planned"] / p["std_random"], p["name"])
        for p in doc["parameters"]
        if p["std_random"]
    ]
    loose = sorted(
        (
            (p["std_planned"] / p["prior_std"], p["name"])
            for p in doc["parameters"]
            if p["prior_std"]
        ),
        reverse=True,
    )[:3]
    if ratios:
        med = sorted(r for r, _ in ratios)[len(ratios) // 2]
        text = f"std        planned / random: median {med:.2f} over the parameters"
        if loose:
            text += "; least determined (std / prior): " + ", ".join(
                f"{name} {r:.2f}" for r, name in loose
            )
        click.echo(text)
    o = doc["order"]
    click.echo(
        f"motion     {o['path_deg']:.0f} deg of largest-joint motion along the plan "
        f"({o['path_unordered_deg']:.0f} in the order chosen)"
    )
    for w in doc["warnings"]:
        click.echo(f"warning    {w}", err=True)
    click.echo(f"wrote      {', '.join(map(str, [out, rep, *(extra or [])]))}")
