"""Shared steps of the real-data examples: convert, cross-validate, print, save.

Not part of the kinecal package: a short, readable recipe for your own data.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from kinecal.identification import (
    CalibrationOptions,
    CrossValidation,
    Measurements,
    cross_validate,
)
from kinecal.io import measurements_to_csv, read_measurements
from kinecal.robot import RobotDescription

HERE = Path(__file__).resolve().parent
DATA = HERE / "data"

# (label, model, priors): the nominal baseline, the paper's plain least squares, and
# kinecal's default (MAP with physical priors) for growing models.
ROWS = (
    ("nominal (frames only)", "nominal", "all"),
    ("kinematic, plain LS", "kinematic", "none"),
    ("kinematic", "kinematic", "all"),
    ("ntm", "ntm", "all"),
    ("full", "full", "all"),
)


def to_kinecal_csv(
    meas: Measurements, robot: RobotDescription, path: Path
) -> Measurements:
    """Write ``meas`` as a kinecal measurement CSV and read it back (validated)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(measurements_to_csv(meas, robot))
    return read_measurements(path, robot)


def cv_table(
    robot: RobotDescription,
    meas: Measurements,
    k: int = 5,
    seed: int = 0,
    *,
    leave_one_out: tuple[str, ...] = (),
) -> list[dict[str, object]]:
    """k-fold cross-validated held-out errors of every row of :data:`ROWS`; the rows
    named in ``leave_one_out`` also leave-one-out (each pose predicted by a calibration
    on all the others: ``loo_rms_mm``)."""
    out = []
    for label, model, priors in ROWS:
        opts = CalibrationOptions(priors=priors)
        cv: CrossValidation = cross_validate(
            robot, meas, model, k=k, seed=seed, options=opts
        )
        rot = [f.rot_rms_deg for f in cv.folds if f.rot_rms_deg is not None]
        row: dict[str, object] = {
            "model": label,
            "cv_rms_mm": round(cv.rms_mm, 4),
            "cv_se_mm": round(cv.rms_se_mm, 4),
            "train_rms_mm": round(float(np.mean([m.rms_mm for m in cv.train])), 4),
            "cv_rot_rms_deg": round(float(np.sqrt(np.mean(np.square(rot)))), 4)
            if rot
            else None,
        }
        if label in leave_one_out:
            loo = cross_validate(robot, meas, model, k=meas.n, options=opts)
            row["loo_rms_mm"] = round(loo.rms_mm, 4)
        out.append(row)
    return out


def print_table(title: str, rows: list[dict[str, object]]) -> None:
    print(title)
    loo = any("loo_rms_mm" in r for r in rows)
    print(
        f"{'model':24s} {'train RMS':>10s} {'CV RMS':>9s} {'+-SE':>7s} {'CV rot':>8s}"
        + (f" {'LOO RMS':>8s}" if loo else "")
    )
    for r in rows:
        rot = "" if r["cv_rot_rms_deg"] is None else f"{r['cv_rot_rms_deg']:.3f}"
        one = f" {r['loo_rms_mm']:8.3f}" if "loo_rms_mm" in r else ""
        print(
            f"{r['model']:24s} {r['train_rms_mm']:10.3f} {r['cv_rms_mm']:9.3f} "
            f"{r['cv_se_mm']:7.3f} {rot:>8s}{one}"
        )
    print(
        "(mm; rotation in deg; CV = 5-fold cross-validated held-out error"
        + ("; LOO = leave-one-out)" if loo else ")")
    )


def save(out: Path, summary: dict[str, object]) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(f"summary: {out / 'summary.json'}")
