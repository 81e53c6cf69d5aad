"""What ``kinecal plan`` reports: report.json (file units: mm, deg) and the summary."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click

from kinecal.cli._common import manifest

__all__ = ["echo_summary", "plan_report"]


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


def plan_report(
    pl: Any,
    kw: dict[str, Any],
    env: dict[str, Any],
    cand: dict[str, Any],
    rows: list[int],
) -> dict[str, Any]:
    """The content of the plan's report.json (file units: mm, deg)."""
    import numpy as np

    from kinecal._version import __version__
    from kinecal.planning import prior_sigma

    pb = pl.problem
    L = pb.model.layout
    free = np.flatnonzero(pb.free)
    ps = prior_sigma(pb.model, kw["priors"])
    params = []
    for k, i in enumerate(free):
        f = L.specs[i].unit.to_file
        params.append(
            {
                "name": L.names[i],
                "unit": L.specs[i].unit.file_unit,
                "std_planned": pl.planned.std[k] * f,
                "std_random": pl.random.std[k] * f,
                "std_before": None if pl.before is None else pl.before.std[k] * f,
                "prior_std": ps[i] * f if np.isfinite(ps[i]) else None,
            }
        )

    def pred(p: Any) -> dict[str, float]:
        return {
            "heldout_rms_mm": p.heldout_rms * 1e3,
            "model_rms_mm": p.model_rms * 1e3,
            "floor_mm": p.floor * 1e3,
            "ratio": p.ratio,
        }

    s = pl.selection
    inst = env["inst"]
    return {
        "kinecal_version": __version__,
        "robot": env["robot"].name,
        "model": pb.model.spec.name,
        "instrument": inst.name,
        "criterion": kw["criterion"],
        "exchange": kw["exchange"],
        "priors": kw["priors"],
        "noise_mm": inst.noise * 1e3,
        "noise_deg": float(np.degrees(inst.noise_rot)) if inst.kind == "pose" else None,
        "n_poses": int(pl.index.size),
        "sequential": None
        if env["cal"] is None
        else {"model": kw["model_name"], "data": kw["data_path"]},
        "candidates": {
            "n": int(cand["q"].shape[0]),
            "source": cand["source"],
            **cand["info"],
        },
        "design": {
            "parameters": pb.size,
            "not_determined": [d.name for d in pb.identifiability.dropped],
            "information": "posterior: sum_c F_c^T F_c + prior precision, F_c = whitened "
            "Jacobian with scaled columns; covariance of the MAP estimate = its inverse",
            "design_point": "calibrated parameters"
            if env["cal"] is not None
            else "nominal kinematics, lambda* = 1e-4 rad/m, link moments 0.3-0.5 m",
        },
        "selection": {
            "value": s.value,
            "greedy_value": s.greedy_value,
            "swaps": s.swaps,
            "sweeps": s.sweeps,
            "seconds": s.seconds,
        },
        "predicted": {
            **pred(pl.planned),
            "formula": "sqrt(3 sigma^2 + tr(M^-1 W)), "
            "W = mean over candidates of G_c^T G_c",
        },
        "random": {
            "draws": int(pl.random.heldout_rms.size),
            "heldout_rms_mm_mean": pl.random.mean_rms * 1e3,
            "heldout_rms_mm_sd": float(np.std(pl.random.heldout_rms) * 1e3),
            "ratio": pl.random.ratio,
        },
        "before": None if pl.before is None else pred(pl.before),
        "parameters": params,
        "order": {
            "candidate_rows": rows,
            "path_deg": float(np.degrees(pl.path)),
            "path_unordered_deg": float(np.degrees(pl.path_unordered)),
        },
        "warnings": pl.warnings,
        "manifest": manifest(
            {
                "candidates": kw["candidates"],
                "targets": kw["targets"],
                "data": kw["data_path"],
            },
            {k: v for k, v in kw.items() if k not in ("quiet", "force", "as_json")},
        ),
    }
