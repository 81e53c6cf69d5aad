"""``kinecal compensate`` (DESIGN §11)."""

from __future__ import annotations

import json
import sys

import click

from kinecal.cli._common import model_file_option


@click.command()
@click.argument("targets", type=click.Path(dir_okay=False))
@model_file_option
@click.option(
    "--out",
    "out_path",
    required=True,
    type=click.Path(dir_okay=False),
    help="CORRECTED.csv: the same rows with corrected joints, err_mm and status.",
)
@click.option(
    "--tol-mm",
    type=float,
    default=0.001,
    show_default=True,
    help="A row is reachable when the model's predicted error is below this [mm].",
)
@click.option(
    "--allow-unreachable",
    is_flag=True,
    help="Write the file even if some rows are unreachable (they are flagged).",
)
@click.option("--json", "as_json", is_flag=True, help="Print a JSON summary.")
@click.option("--force", is_flag=True, help="Overwrite --out.")
def compensate(
    targets: str,
    model_path: str,
    out_path: str,
    tol_mm: float,
    allow_unreachable: bool,
    as_json: bool,
    force: bool,
) -> None:
    """Corrected controller angles so the robot reaches TARGETS.csv.

    TARGETS has x_mm, y_mm, z_mm (tool point wanted in the user frame; optional qw..qz)
    and the program's nominal joints j1_deg..jN_deg as seeds (they pick the IK branch).
    Position-only targets keep the seed's tool orientation. Unreachable or out-of-limit
    rows are listed and the command exits with code 4 unless --allow-unreachable.
    """
    import numpy as np

    from kinecal.cli import EXIT_UNREACHABLE
    from kinecal.compensation import compensate as run_compensation
    from kinecal.io import atomic_write_text, load_model, read_compensation_targets

    cal = load_model(model_path)
    tg = read_compensation_targets(targets, cal.model.robot)
    spec = cal.model.spec
    set_index = _map_labels(tg.set_labels, tg.set_index, spec.sets, targets, "set")
    marker_index = _map_labels(
        tg.marker_labels, tg.marker_index, spec.markers, targets, "marker"
    )
    res = run_compensation(
        cal,
        tg.p,
        tg.q_seed,
        R_target=tg.R,
        set_index=set_index,
        marker_index=marker_index,
        tol=tol_mm * 1e-3,
    )
    bad = np.flatnonzero(~res.ok)
    for i in bad[:50]:
        click.echo(
            f"{targets}: line {tg.table.lines[i]}: {res.status[i]}: target "
            f"({tg.p[i, 0] * 1e3:.3f}, {tg.p[i, 1] * 1e3:.3f}, {tg.p[i, 2] * 1e3:.3f}) mm, "
            f"predicted error {res.error[i] * 1e3:.4f} mm",
            err=True,
        )
    if bad.size > 50:
        click.echo(f"... and {bad.size - 50} more rows", err=True)
    summary = {
        "n": int(tg.p.shape[0]),
        "ok": int(res.ok.sum()),
        "unreachable": int(bad.size),
        "max_err_mm": float(res.error[res.ok].max() * 1e3) if res.ok.any() else None,
        "out": out_path,
    }
    if bad.size and not allow_unreachable:
        summary["out"] = None
        click.echo(
            json.dumps(summary)
            if as_json
            else f"{bad.size} of {summary['n']} targets cannot be reached; nothing written "
            "(use --allow-unreachable to write them flagged)."
        )
        sys.exit(EXIT_UNREACHABLE)
    header = list(tg.table.header)
    cols = {c: header.index(c) for c in tg.joint_columns}
    lines = [",".join([*header, "err_mm", "status"])]
    for i, row in enumerate(tg.table.rows):
        out = list(row)
        for k, c in enumerate(tg.joint_columns):
            unit = c.rsplit("_", 1)[1]
            v = res.q_ctrl[i, k]
            val = {"deg": np.degrees(v), "rad": v, "mm": v * 1e3, "m": v}[unit]
            out[cols[c]] = f"{val:.8f}"
        lines.append(",".join([*out, f"{res.error[i] * 1e3:.6f}", str(res.status[i])]))
    atomic_write_text(out_path, "\n".join(lines) + "\n", force=force)
    if as_json:
        click.echo(json.dumps(summary))
    else:
        click.echo(
            f"{summary['ok']} of {summary['n']} targets compensated; "
            f"largest predicted error {summary['max_err_mm'] or 0:.6f} mm; wrote {out_path}"
        )


def _map_labels(labels, index, own, path, what):
    """Map the file's set/marker labels onto the model's (one frame: any label)."""
    import numpy as np

    from kinecal.errors import DataError

    if len(own) == 1:
        return np.zeros(index.shape[0], np.intp)
    missing = [lab for lab in labels if lab not in own]
    if missing:
        raise DataError(
            f"{path}: {what} {missing[0]!r} is not in the model ({', '.join(own)})."
        )
    return np.array([own.index(lab) for lab in labels], np.intp)[index]
