"""Breakdown study of the robust estimation (issue 25): ``python -m benchmarks --robust``.

On the digital twin, a fraction (0, 1, 5, 10, 20 %) of the calibration rows is moved by a
gross error of 1, 5 or 50 mm (``kinecal.simulation.add_outliers``: a random direction,
1-3 times the size), for point (laser tracker, experiment 2: 100 poses), pose (6-D
tracker, 120 poses of a random true robot) and sensor data (experiment 1: 100 poses); plus
a single wild row (a joint at 1e300, a joint written in radians into a degree column).
Each case is calibrated (full model) three ways: rejection on (the default), rejection off
(plain least squares, the rows only reported) and rejection off with a Huber loss, and
scored on held-out poses. The table gives the held-out RMS over the clean fit's, and for
the default whether the rejected rows are exactly the moved ones.
"""

from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.identification import CalibrationOptions, Measurements, calibrate, evaluate
from kinecal.robot import load_robot
from kinecal.simulation import (
    PoseTracker,
    add_outliers,
    experiment1,
    experiment2,
    random_truth,
)

FRACTIONS = (0.0, 0.01, 0.05, 0.10, 0.20)
SIZES_MM = (1.0, 5.0, 50.0)
METHODS = {
    "reject": CalibrationOptions(),
    "plain": CalibrationOptions(reject="off"),
    "huber": CalibrationOptions(reject="off", loss="huber"),
}
OFFSET_DEG = np.array([0.0, 10.0, 0.0, 0.0, -60.0, 0.0])


def _pose_twin(seed: int) -> tuple[Measurements, Measurements]:
    robot = load_robot("fanuc-lrmate200id")
    truth = random_truth(robot, seed=seed)
    rng = np.random.default_rng(seed + 100)

    def draw(n: int) -> Measurements:
        q = np.radians(rng.uniform(-50, 50, size=(n, 6)) + OFFSET_DEG)
        p, R = truth.evaluate(q, orientation=True)
        pm, Rm = PoseTracker(30e-6, 3e-4).measure(p, R, rng)
        return Measurements("pose", q, pm, R_user_cam=Rm)

    return draw(120), draw(1000)


def _twins(seed: int) -> dict[str, tuple[Measurements, Measurements]]:
    e2 = experiment2(seed)
    e1 = experiment1(seed)
    return {
        "point": (e2.train, e2.test.subset(np.arange(0, e2.test.n, 5))),
        "pose": _pose_twin(seed),
        "sensor": (e1.train, e1.test),
    }


def _case(robot: Any, train: Measurements, test: Measurements, moved: set[int]) -> dict:
    out: dict[str, Any] = {}
    for name, opts in METHODS.items():
        t0 = time.perf_counter()
        try:
            res = calibrate(robot, train, "full", opts)
        except ValueError as exc:  # a ruined fit may not converge at all
            out[name] = {"error": str(exc)}
            continue
        held = evaluate(res.calibrated, test).metrics.rms_mm
        out[name] = {
            "heldout_rms_mm": held,
            "seconds": time.perf_counter() - t0,
            "rejected": sorted(o.row for o in res.rejected),
        }
    rej = set(out["reject"].get("rejected", []))
    out["exact"] = rej == moved
    out["clean_rejected"] = len(rej - moved)
    out["missed"] = len(moved - rej)
    return out


def main(args: Any) -> int:
    robot = load_robot("fanuc-lrmate200id")
    seed = 0
    results: dict[str, Any] = {"cases": []}
    for kind, (train, test) in _twins(seed).items():
        clean = _case(robot, train, test, set())
        base = clean["reject"]["heldout_rms_mm"]
        for size in SIZES_MM:
            for frac in FRACTIONS[1:]:
                rng = np.random.default_rng(1000 + int(frac * 100) + int(size))
                p, idx = add_outliers(train.p, rng, frac, size=size * 1e-3)
                moved = set(train.rows[idx].tolist())
                row = _case(robot, replace(train, p=p), test, moved)
                row.update(kind=kind, size_mm=size, fraction=frac, clean_mm=base)
                results["cases"].append(row)
                print(_line(row), flush=True)
        for wild in ("joint 1e300", "joint in radians"):
            q = train.q_ctrl.copy()
            q[17, 1] = 1e300 if wild == "joint 1e300" else np.radians(q[17, 1])
            row = _case(robot, replace(train, q_ctrl=q), test, {int(train.rows[17])})
            row.update(kind=kind, size_mm=None, fraction=None, wild=wild, clean_mm=base)
            results["cases"].append(row)
            print(_line(row), flush=True)
    Path(args.out).write_text(json.dumps(results, indent=1))
    print(f"wrote {args.out}")
    return 0


def _line(row: dict) -> str:
    what = row.get("wild") or f"{row['fraction']:.0%} x {row['size_mm']:g} mm"
    parts = [f"{row['kind']:6s} {what:16s}"]
    for name in METHODS:
        r = row[name]
        ratio = r["heldout_rms_mm"] / row["clean_mm"] if "heldout_rms_mm" in r else None
        parts.append(f"{name} {ratio:8.3g}x" if ratio is not None else f"{name} failed")
    parts.append("exact" if row["exact"] else f"missed {row['missed']}")
    return "  ".join(parts)
