"""Pose planning study (issue 22): ``python -m benchmarks --planning``.

On the digital twin (the paper's true robot, :mod:`kinecal.simulation`), for each number
of poses N the full model is calibrated from N poses chosen by ``kinecal plan``
(I-optimal, Fedorov exchange) and from N random poses of the same candidates, and
evaluated on every other candidate; the held-out RMS is divided by the noise floor (the
RMS of the 3-D noise, sqrt(3) sigma per axis). Each planned design is measured with
several noise realisations (seeds), each random one is a new draw per seed.

* tracker: experiment 2, 7 orientations x 10^3 grid (6955 reachable poses), tracker noise
  5 um per axis (the issue-4 tests' floor 8.66 um);
* sensor: the four ceramic spheres of experiment 1, 2000 views (500 per sphere) at the
  115-135 mm working distance, the sensor's 4/4/8 um noise (floor 9.80 um).

Also times ``kinecal plan`` choosing 30 of the 6955 tracker candidates as a whole process.
Writes JSON (``--out``) and, with ``--figures DIR``, the figures of ``docs/planning.md``.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from kinecal.identification import Measurements, calibrate, evaluate
from kinecal.planning import Instrument, plan_poses, planning_model
from kinecal.simulation import (
    CERAMIC_SPHERES_MM,
    LaserTracker,
    SphereSensor,
    experiment2,
    paper_truth,
    sphere_poses,
)
from kinecal.simulation import planning_model as twin_planning_model

TRACKER_NOISE = 5e-6  # m per axis
SENSOR = SphereSensor()  # 4, 4, 8 um in the cam frame
# Calibrating the full model needs more residuals than parameters: 17 tracker poses
# (50 parameters, 3 rows each), 18 sensor poses (53 parameters).
TRACKER_NS = (17, 20, 30, 50, 100)
SENSOR_NS = (18, 20, 30, 50, 100)


def _heldout(robot: Any, meas: Measurements, rows: np.ndarray) -> float:
    """Held-out RMS [mm] of the full model calibrated on ``rows``."""
    res = calibrate(robot, meas.subset(rows), "full")
    rest = np.setdiff1d(np.arange(meas.n), rows)
    return evaluate(res.calibrated, meas.subset(rest)).metrics.rms_mm


def _study(
    name: str,
    ns: tuple[int, ...],
    seeds: int,
    draws: int,
    plan_for: Any,
    measure: Any,
    n_candidates: int,
    floor_mm: float,
    robot: Any,
) -> dict[str, Any]:
    rows: list[dict[str, Any]] = []
    for n in ns:
        t0 = time.perf_counter()
        pl = plan_for(n)
        t_plan = time.perf_counter() - t0
        planned, rand = [], []
        for s in range(seeds):
            meas = measure(s)
            planned.append(_heldout(robot, meas, pl.index) / floor_mm)
            rng = np.random.default_rng(1000 + s)
            for _ in range(draws):
                pick = rng.choice(n_candidates, n, replace=False)
                rand.append(_heldout(robot, meas, pick) / floor_mm)
        row = {
            "n": n,
            "planned_ratio_mean": float(np.mean(planned)),
            "planned_ratio_sd": float(np.std(planned, ddof=1)) if seeds > 1 else 0.0,
            "planned_ratio": planned,
            "random_ratio_mean": float(np.mean(rand)),
            "random_ratio_sd": float(np.std(rand, ddof=1)) if len(rand) > 1 else 0.0,
            "random_ratio": rand,
            "predicted_planned_ratio": pl.planned.ratio,
            "predicted_random_ratio": pl.random.ratio,
            "plan_seconds": t_plan,
            "swaps": pl.selection.swaps,
        }
        rows.append(row)
        print(
            f"  {name:8s} N={n:4d}  planned {row['planned_ratio_mean']:.3f} "
            f"(pred {pl.planned.ratio:.3f})  random {row['random_ratio_mean']:.3f} "
            f"(pred {pl.random.ratio:.3f})  plan {t_plan:.2f} s",
            flush=True,
        )
    return {
        "candidates": n_candidates,
        "floor_mm": floor_mm,
        "seeds": seeds,
        "random_draws_per_seed": draws,
        "rows": rows,
    }


def tracker_study(ns=TRACKER_NS, seeds: int = 6, draws: int = 2, n_side: int = 10):
    """Experiment 2's grid as candidates; planned vs random for each N."""
    e0 = experiment2(0, tracker=LaserTracker(TRACKER_NOISE, 0.0), n_side=n_side)
    q = e0.plan.q_ctrl
    pm, x = twin_planning_model(e0.truth)
    inst = Instrument("tracker", TRACKER_NOISE)
    cm, params = planning_model(e0.truth.robot, "full", inst)
    params[cm.base_index[0]] = x[pm.base_index[0]]
    params[cm.cam_index[0]] = x[pm.cam_index[0][:3]]

    def measure(seed: int) -> Measurements:
        rng = np.random.default_rng(seed)
        p_true, _ = e0.truth.evaluate(q, sequence=np.arange(q.shape[0]))
        p, sig = LaserTracker(TRACKER_NOISE, 0.0).measure(p_true, rng)
        return Measurements("point", q, p, sigma=sig, rows=np.arange(1, q.shape[0] + 1))

    return _study(
        "tracker",
        ns,
        seeds,
        draws,
        lambda n: plan_poses(cm, params, q, n, inst),
        measure,
        q.shape[0],
        TRACKER_NOISE * np.sqrt(3) * 1e3,
        e0.truth.robot,
    )


def criteria_study(n: int = 30, seeds: int = 4) -> dict[str, Any]:
    """Tracker twin, n of the 6955 poses: each criterion and exchange, its predicted
    held-out ratio (the I criterion's measure), the measured one and the time."""
    e0 = experiment2(0, tracker=LaserTracker(TRACKER_NOISE, 0.0))
    q = e0.plan.q_ctrl
    pm, x = twin_planning_model(e0.truth)
    inst = Instrument("tracker", TRACKER_NOISE)
    cm, params = planning_model(e0.truth.robot, "full", inst)
    params[cm.base_index[0]] = x[pm.base_index[0]]
    params[cm.cam_index[0]] = x[pm.cam_index[0][:3]]
    meas = []
    for seed in range(seeds):
        p_true, _ = e0.truth.evaluate(q)
        p, sig = LaserTracker(TRACKER_NOISE, 0.0).measure(
            p_true, np.random.default_rng(seed)
        )
        rows = np.arange(1, q.shape[0] + 1)
        meas.append(Measurements("point", q, p, sigma=sig, rows=rows))
    floor = TRACKER_NOISE * np.sqrt(3) * 1e3
    out = []
    cases = [(c, "fedorov") for c in ("I", "D", "A", "E", "G")]
    cases += [("I", "none"), ("I", "detmax")]
    for crit, exch in cases:
        t0 = time.perf_counter()
        pl = plan_poses(cm, params, q, n, inst, criterion=crit, exchange=exch)
        dt = time.perf_counter() - t0
        got = [_heldout(e0.truth.robot, m, pl.index) / floor for m in meas]
        out.append(
            {
                "criterion": crit,
                "exchange": exch,
                "seconds": dt,
                "predicted_ratio": pl.planned.ratio,
                "measured_ratio_mean": float(np.mean(got)),
                "measured_ratio": got,
            }
        )
        print(
            f"  {crit}-optimal {exch:8s} predicted {pl.planned.ratio:.3f} measured "
            f"{np.mean(got):.3f}  {dt:.2f} s",
            flush=True,
        )
    return {"n": n, "candidates": int(q.shape[0]), "seeds": seeds, "rows": out}


def sensor_study(ns=SENSOR_NS, seeds: int = 6, draws: int = 2, per_sphere: int = 500):
    """Views of the four ceramic spheres as candidates; planned vs random for each N."""
    truth = paper_truth(1)
    pm, x = twin_planning_model(truth)
    spheres = CERAMIC_SPHERES_MM[:, :3] * 1e-3
    views = sphere_poses(
        pm, x, spheres, np.random.default_rng(0), per_sphere=per_sphere
    )
    q, ti = views.q_ctrl, views.label
    s_axis = float(np.sqrt((2 * SENSOR.sigma_xy**2 + SENSOR.sigma_z**2) / 3))
    inst = Instrument("sensor", s_axis, targets=spheres)
    cm, params = planning_model(truth.robot, "full", inst)
    params[cm.base_index[0]] = x[pm.base_index[0]]
    params[cm.cam_index[0]] = x[pm.cam_index[0]]
    p0, R = truth.evaluate(q, orientation=True)
    assert R is not None
    p_cam_true = np.einsum("nji,nj->ni", R, spheres[ti] - p0)

    def measure(seed: int) -> Measurements:
        rng = np.random.default_rng(seed)
        return Measurements(
            "sensor",
            q,
            SENSOR.measure(p_cam_true, rng),
            target_index=ti,
            targets=spheres,
            target_labels=("S1", "S2", "S3", "S4"),
            rows=np.arange(1, q.shape[0] + 1),
        )

    floor = float(np.sqrt(2 * SENSOR.sigma_xy**2 + SENSOR.sigma_z**2)) * 1e3
    return _study(
        "sensor",
        ns,
        seeds,
        draws,
        lambda n: plan_poses(cm, params, q, n, inst, target_index=ti),
        measure,
        q.shape[0],
        floor,
        truth.robot,
    )


def cli_speed(repeat: int = 5, n: int = 30) -> dict[str, Any]:
    """``kinecal plan`` choosing n of the 6955 experiment-2 poses, as a whole process."""
    e = experiment2(0)
    q = np.degrees(e.plan.q_ctrl)
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    with tempfile.TemporaryDirectory() as tmp:
        cand = Path(tmp) / "cand.csv"
        lines = [",".join(f"j{k}_deg" for k in range(1, 7))]
        lines += [",".join(f"{v:.6f}" for v in r) for r in q]
        cand.write_text("\n".join(lines) + "\n")
        cmd = [sys.executable, "-m", "kinecal", "plan", "--robot", "fanuc-lrmate200id"]
        cmd += ["--candidates", str(cand), "--poses", str(n), "--force", "-q"]
        cmd += ["--out", str(Path(tmp) / "plan.csv"), "--tool", "44.2,-60.5,104"]
        subprocess.run(cmd, check=True, capture_output=True, env=env)  # warm-up
        walls, cpus = [], []
        for _ in range(repeat):
            r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, capture_output=True, env=env)
            walls.append(time.perf_counter() - t0)
            r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpus.append(r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
        rep = json.loads((Path(tmp) / "plan.report.json").read_text())
    out = {
        "candidates": int(q.shape[0]),
        "poses": n,
        "seconds": statistics.median(walls),
        "best_seconds": min(walls),
        "cpu_seconds": statistics.median(cpus),
        "selection_seconds": rep["selection"]["seconds"],
        "target": "< 10 s on 2 cores, whole process",
        "cpus": os.cpu_count(),
        "load_average": os.getloadavg(),
    }
    print(
        f"  kinecal plan {n} of {q.shape[0]}: {out['seconds']:.2f} s wall (median of "
        f"{repeat}), {out['cpu_seconds']:.2f} s CPU",
        flush=True,
    )
    return out


def figures(results: dict[str, Any], outdir: Path) -> list[Path]:
    """Held-out RMS / floor against N, planned vs random, measured and predicted."""
    import matplotlib
    import matplotlib.ticker

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    for key, title in (
        ("tracker", "laser tracker (experiment 2)"),
        ("sensor", "3D sensor, four spheres (experiment 1)"),
    ):
        if key not in results:
            continue
        rows = results[key]["rows"]
        n = np.array([r["n"] for r in rows])
        fig, ax = plt.subplots(figsize=(5.6, 3.8), dpi=110)
        for what, color, label in (
            ("random", "tab:red", "random"),
            ("planned", "tab:blue", "planned (I-optimal)"),
        ):
            m = np.array([r[f"{what}_ratio_mean"] for r in rows])
            sd = np.array([r[f"{what}_ratio_sd"] for r in rows])
            ax.errorbar(
                n,
                m,
                yerr=sd,
                color=color,
                marker="o",
                capsize=3,
                label=f"{label}, measured",
            )
            pred = np.array([r[f"predicted_{what}_ratio"] for r in rows])
            ax.plot(n, pred, color=color, ls="--", lw=1, label=f"{label}, predicted")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_xticks(n)
        ax.set_xticklabels([str(v) for v in n])
        top = max(
            max(r[f"{w}_ratio_mean"] + r[f"{w}_ratio_sd"] for r in rows)
            for w in ("planned", "random")
        )
        yt = [v for v in (1, 1.2, 1.5, 2, 3, 5, 10, 20) if v <= max(top, 1.5) * 1.05]
        ax.set_yticks(yt)
        ax.set_yticklabels([f"{v:g}" for v in yt])
        ax.set_xlabel("poses N")
        ax.set_ylabel("held-out RMS / noise floor")
        ax.set_title(f"Full model, {title}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        p = outdir / f"planning_{key}.png"
        fig.savefig(p)
        plt.close(fig)
        paths.append(p)
    return paths


def main(args: Any) -> int:
    """Run the study (``--quick``: fewer seeds and sizes) and write the JSON."""
    quick = bool(getattr(args, "quick", False))
    seeds, draws = (2, 1) if quick else (6, 2)
    results: dict[str, Any] = {}
    print("pose planning study (issue 22)", flush=True)
    results["cli_plan_30_of_6955"] = cli_speed(2 if quick else 5)
    results["tracker"] = tracker_study(
        (20, 30) if quick else TRACKER_NS, seeds=seeds, draws=draws
    )
    results["criteria"] = criteria_study(30, seeds=2 if quick else 4)
    results["sensor"] = sensor_study(
        (20, 30) if quick else SENSOR_NS, seeds=seeds, draws=draws
    )
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".tmp")
    tmp.write_text(
        json.dumps({"created_unix": time.time(), **results}, indent=2) + "\n"
    )
    os.replace(tmp, out)
    print(f"-> {out}")
    if getattr(args, "figures", None):
        for p in figures(results, Path(args.figures)):
            print(f"-> {p}")
    return 0
