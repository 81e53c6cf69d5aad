"""``kinecal report --compare OLD_DIR NEW_DIR`` (issue 38 point 4b): two calibrations of
one robot side by side: the parameters that moved beyond their combined uncertainty, and
each model's accuracy on the other's data (when those files are still where the
manifests say and unchanged), to see drift between recalibrations at a glance."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from kinecal.io._json_read import loads
from kinecal.report._format import e, num, page, pm, ratio, table
from kinecal.report._tables import SIGNIFICANT, name_cell

__all__ = ["compare_calibrations", "render_comparison"]


def _load(d: Path) -> dict[str, Any]:
    from kinecal.errors import DataError
    from kinecal.io import load_model

    if not d.is_dir():
        raise DataError(f"{d}: no such folder; expected a folder of kinecal calibrate.")
    man_path = d / "manifest.json"
    try:
        man = loads(man_path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        man = {}
    except json.JSONDecodeError as exc:
        raise DataError(f"{man_path}: not valid JSON ({exc}).") from None
    return {"dir": d, "cal": load_model(d / "model.yaml"), "manifest": man}


def _robot_key(side: dict[str, Any]) -> tuple[str, str | None]:
    meta = side["manifest"].get("meta") or {}
    serial = meta.get("serial") or meta.get("robot_serial")
    return side["cal"].model.robot.name, serial


def _data(side: dict[str, Any]) -> tuple[Any, str]:
    """The measurements the side was calibrated on, or None with the reason."""
    from kinecal.io import file_sha256, read_data

    inputs = side["manifest"].get("inputs") or {}
    rec = inputs.get("data")
    if not rec:
        return None, "its manifest names no data file"
    path = Path(rec["path"])
    if not path.is_absolute() and not path.is_file():
        path = side["dir"] / path
    if not path.is_file():
        return None, f"{rec['path']} is not there any more"
    if rec.get("sha256") and file_sha256(path) != rec["sha256"]:
        return None, f"{path} changed since the calibration (SHA-256 differs)"
    tg = inputs.get("targets")
    meas, _ = read_data(
        str(path),
        side["cal"].model.robot,
        tg["path"] if tg else None,
        allow_out_of_limits=True,
    )
    return meas, str(path)


def compare_calibrations(old_dir: str | Path, new_dir: str | Path) -> dict[str, Any]:
    """The comparison as a dict (what the HTML page and the console show).

    Raises
    ------
    DataError
        A folder is not a calibration result, or the two are of different robots
        (robot model or ``--meta serial``).
    """
    from kinecal.errors import DataError
    from kinecal.identification import evaluate
    from kinecal.io import parameter_records

    old, new = _load(Path(old_dir)), _load(Path(new_dir))
    (ro, so), (rn, sn) = _robot_key(old), _robot_key(new)
    if ro != rn or (so and sn and so != sn):
        raise DataError(
            f"{old_dir} and {new_dir} are calibrations of different robots "
            f"({ro}{f' serial {so}' if so else ''} and {rn}"
            f"{f' serial {sn}' if sn else ''}); expected two of one robot."
        )
    po = {r["name"]: r for r in parameter_records(old["cal"])}
    params = []
    for r in parameter_records(new["cal"]):
        o = po.get(r["name"])
        if o is None:
            continue
        d = r["value"] - o["value"]
        sds = [s for s in (r["std"], o["std"]) if s is not None and math.isfinite(s)]
        both = r["status"] == o["status"] == "estimated" and len(sds) == 2
        comb = math.sqrt(sum(s * s for s in sds)) if both else None
        z = abs(d) / comb if comb else None
        params.append(
            {
                "name": r["name"],
                **({"joint_name": r["joint_name"]} if "joint_name" in r else {}),
                "unit": r["unit"],
                "old": o["value"],
                "old_std": o["std"],
                "new": r["value"],
                "new_std": r["std"],
                "change": d,
                "combined_std": comb,
                "z": z,
                "moved": bool(z is not None and z > SIGNIFICANT),
            }
        )
    cross = []
    data = {"old": _data(old), "new": _data(new)}
    for model_side, data_side in (
        ("old", "old"),
        ("new", "old"),
        ("new", "new"),
        ("old", "new"),
    ):
        meas, where = data[data_side]
        row: dict[str, Any] = {"model": model_side, "data": data_side}
        if meas is None:
            row["skipped"] = where
        else:
            cal = (old if model_side == "old" else new)["cal"]
            # the other session's tracker stood elsewhere: its user frame is refitted
            ev = evaluate(cal, meas, refit_user=model_side != data_side)
            row.update(
                rms_mm=ev.metrics.rms_mm,
                max_mm=ev.metrics.max_mm,
                n=ev.metrics.n,
                refit_user=model_side != data_side,
                path=where,
            )
        cross.append(row)
    return {
        "old": str(old_dir),
        "new": str(new_dir),
        "robot": rn,
        "significance": SIGNIFICANT,
        "parameters": params,
        "moved": [p["name"] for p in params if p["moved"]],
        "cross": cross,
    }


def render_comparison(c: dict[str, Any]) -> str:
    moved = [p for p in c["parameters"] if p["moved"]]
    rows = [
        [
            name_cell(p),
            e(p["unit"]),
            pm(p["old"], p["old_std"]),
            pm(p["new"], p["new_std"]),
            num(p["change"]),
            num(p["combined_std"]),
            ratio(p["z"]),
        ]
        for p in c["parameters"]
    ]
    cls = ["sig" if p["moved"] else "" for p in c["parameters"]]
    head = ["parameter", "unit", "old", "new", "change", "combined std"]
    head += ["|change| / std"]
    acc = []
    for r in c["cross"]:
        label = f"{r['model']} model on {r['data']} data"
        if "skipped" in r:
            acc.append([e(label), "—", "—", "—", e(f"not computed: {r['skipped']}")])
        else:
            note = "user frame refitted" if r["refit_user"] else "its own data"
            acc.append(
                [e(label), e(r["n"]), num(r["rms_mm"]), num(r["max_mm"]), e(note)]
            )
    body = [
        "<div class=box>",
        f"<p><b>{e(c['robot'])}</b>: {e(c['old'])} (old) and {e(c['new'])} (new). "
        f"<b>{len(moved)}</b> of {len(c['parameters'])} parameters moved beyond "
        f"{c['significance']:g} times their combined standard deviation"
        + (f": {e(', '.join(p['name'] for p in moved))}" if moved else "")
        + ".</p></div>",
        "<h2 id=accuracy>Accuracy of each model on each calibration's data</h2>",
        table(["model / data", "poses", "RMS [mm]", "max [mm]", "note"], acc),
        "<h2 id=parameters>Parameters, old and new</h2>",
        "<p class=muted>Highlighted: |change| above "
        f"{c['significance']:g} × √(std_old² + std_new²).</p>",
        table(head, rows, cls=cls),
    ]
    return page(f"kinecal: two calibrations of {c['robot']}", "".join(body))
