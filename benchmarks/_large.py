"""Issue 26 benchmarks: large data, ``--model auto`` against one calibration, start-up.

``python -m benchmarks --issue26 [--out FILE]`` runs them and merges their rows into
FILE (the other rows stay). A large calibration runs in a fresh process
(``python -m benchmarks._large DATA.npz OUT.json``) that loads simulated poses and
calibrates them, so its peak RSS (``ru_maxrss``) is the data's and the calibration's
only, and its CPU time (user + system) is its own: the VM is shared, and CPU time is
what an idle machine would take as wall time (the compiled kernel's second thread
aside).
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
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np


def simulate(n: int, path: Path, seed: int = 1) -> None:
    """``n`` tracker measurements of the experiment-2 twin's truth (the paper's Table 7
    values with its noise) at random joint values within experiment 2's ranges."""
    from kinecal.simulation import LaserTracker, experiment2, paper_truth

    truth = paper_truth(2, seed=0)
    e = experiment2(0, truth=truth)
    q0 = np.concatenate([e.train.q_ctrl, e.test.q_ctrl])
    lo, hi = q0.min(axis=0), q0.max(axis=0)
    rng = np.random.default_rng(seed)
    q = lo + (hi - lo) * rng.random((n, q0.shape[1]))
    p, _ = truth.evaluate(q)
    p, sigma = LaserTracker().measure(p, rng)
    np.savez(path, q=q, p=p, sigma=sigma)


def main(argv: list[str]) -> int:
    """Worker: calibrate the poses of ``argv[0]`` (npz) with the full model and write
    what it took to ``argv[1]`` (JSON)."""
    from kinecal.identification import Measurements, calibrate
    from kinecal.robot import load_robot

    data = np.load(argv[0])
    meas = Measurements(
        "point", data["q"], data["p"], sigma=data["sigma"], source="simulated"
    )
    del data
    gaps: list[float] = []
    last = [time.perf_counter()]

    def progress(stage: str, detail: str) -> None:
        now = time.perf_counter()
        gaps.append(now - last[0])
        last[0] = now

    t0, c0 = time.perf_counter(), time.process_time()
    res = calibrate(load_robot("fanuc-lrmate200id"), meas, "full", progress=progress)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    gaps.append(time.perf_counter() - last[0])
    Path(argv[1]).write_text(
        json.dumps(
            {
                "poses": meas.n,
                "seconds": wall,
                "cpu_seconds": cpu,
                "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                / 1024,
                "rms_mm": res.metrics_after.rms_mm,
                "success": res.success,
                "iterations": {s.name: s.iterations for s in res.stages},
                "progress_lines": len(gaps),
                "longest_silence_s": max(gaps),
            }
        )
    )
    return 0


def large_cases(record: Callable[..., None], sizes: tuple[int, ...]) -> None:
    """A calibration of each size in a fresh process (see the module docstring)."""
    for n in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            data, out = Path(tmp) / "poses.npz", Path(tmp) / "out.json"
            simulate(n, data)
            load = os.getloadavg()[0]
            cmd = [sys.executable, "-m", "benchmarks._large", str(data), str(out)]
            subprocess.run(
                cmd, check=True, env={**os.environ, "OPENBLAS_NUM_THREADS": "1"}
            )
            r: dict[str, Any] = json.loads(out.read_text())
        record(
            f"calibrate_full_{n:.0e}_process".replace("+0", ""),
            r.pop("seconds"),
            "1e6 poses: < 60 s and < 2 GB peak RSS" if n >= 10**6 else "linear in N",
            load_average=load,
            **r,
        )


def whole_commands(
    record: Callable[..., None], robot: Any, meas: Any, repeat: int
) -> None:
    """``kinecal calibrate --model auto`` against ``--model full`` as whole processes
    with their default reports (what a user waits for), run in turn: wall and CPU
    seconds and their ratios pair by pair (medians)."""
    from benchmarks._common import _run
    from kinecal.io import measurements_to_csv

    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / "poses.csv"
        csv.write_text(measurements_to_csv(meas, robot))
        base = [sys.executable, "-m", "kinecal", "calibrate", str(csv), "--robot"]
        base += [robot.name, "--force", "-q", "--out"]
        cmds = {m: [*base, str(Path(tmp) / m), "--model", m] for m in ("full", "auto")}
        for cmd in cmds.values():
            _run(cmd)  # warm-up: bytecode cache
        runs: dict[str, list[tuple[float, float]]] = {m: [] for m in cmds}
        for _ in range(repeat):
            for m, cmd in cmds.items():
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                t = time.perf_counter()
                _run(cmd)
                wall = time.perf_counter() - t
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = (
                    after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
                )
                runs[m].append((wall, cpu))
    med = {
        m: [statistics.median(v[i] for v in r) for i in (0, 1)] for m, r in runs.items()
    }
    pairs = list(zip(runs["auto"], runs["full"]))
    record(
        "calibrate_cli_auto_vs_full_2000",
        med["auto"][0],
        "<= 3x one calibration, as whole commands with their reports",
        cpu_seconds=med["auto"][1],
        full_wall_seconds=med["full"][0],
        full_cpu_seconds=med["full"][1],
        wall_ratio=statistics.median(a[0] / f[0] for a, f in pairs),
        cpu_ratio=statistics.median(a[1] / f[1] for a, f in pairs),
        load_average=os.getloadavg()[0],
    )


def issue26(path: str) -> int:
    """The issue-26 rows, merged into the results file ``path`` (its other rows kept):
    calibrations of 1e5 and 1e6 poses in fresh processes, ``--model auto`` against one
    calibration on 2000 poses (CPU time: the VM is shared), and the start-up of
    ``kinecal --help`` and ``kinecal fk``."""
    from benchmarks._common import _machine, _run
    from kinecal._parallel import available_cpus
    from kinecal.identification import calibrate, select_model
    from kinecal.simulation import LaserTracker, experiment2

    out_path = Path(path)
    old = json.loads(out_path.read_text()) if out_path.is_file() else {}
    results: dict[str, dict[str, Any]] = dict(old.get("results", {}))

    def record(name: str, seconds: float, target: str, **extra: Any) -> None:
        results[name] = {"seconds": float(seconds), "target": target, **extra}
        print(f"  {name:38s} {seconds:10.3f} s   ({target}) {extra}", flush=True)

    def cpu_and_wall(fn: Callable[[], Any], repeat: int) -> tuple[float, float, Any]:
        cpus, walls, out = [], [], None
        for _ in range(repeat):
            t, c = time.perf_counter(), time.process_time()
            out = fn()
            walls.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
        return statistics.median(cpus), statistics.median(walls), out

    print("kinecal issue-26 benchmarks", json.dumps(_machine()), flush=True)
    e = experiment2(3, tracker=LaserTracker(5e-6, 0.0))
    robot, big = e.truth.robot, e.test
    sub = big.subset(np.random.default_rng(1).permutation(big.n)[:2000])
    c1, w1, _ = cpu_and_wall(lambda: calibrate(robot, sub, "full"), 5)
    record("calibrate_full_2000_cpu", c1, "CPU time of one calibration", wall=w1)
    ca, wa, sel = cpu_and_wall(lambda: select_model(robot, sub, jobs=1), 3)
    record(
        "select_model_auto_2000_serial_cpu",
        ca,
        "<= 3x one calibration",
        wall=wa,
        ratio_to_calibration=ca / c1,
        chosen=sel.spec.name,
    )
    whole_commands(record, robot, sub, 7)
    cpus = available_cpus()
    t0 = time.perf_counter()
    seln = select_model(robot, sub, jobs=cpus)
    record(
        "select_model_auto_2000_workers_wall",
        time.perf_counter() - t0,
        "one worker process per CPU (wall, shared VM)",
        workers=cpus,
        same_choice=sel.as_dict() == seln.as_dict(),
        load_average=os.getloadavg()[0],
    )
    fk = ["fk", "--robot", "fanuc-lrmate200id", "--json", "--", "0", "0", "0", "0"]
    for name, cmd in (
        ("cli_help_startup", ["--help"]),
        ("cli_fk_startup", [*fk, "-90", "0"]),
    ):
        full = [sys.executable, "-m", "kinecal", *cmd]
        _run(full)  # warm-up: bytecode cache
        usage, walls = [], []
        for _ in range(15):
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t = time.perf_counter()
            _run(full)
            walls.append(time.perf_counter() - t)
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            usage.append(
                after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
            )
        record(
            name,
            statistics.median(walls),
            "< 0.1 s unloaded",
            cpu_seconds=statistics.median(usage),
            best_seconds=min(walls),
            load_average=os.getloadavg()[0],
        )
    large_cases(record, (10**5, 10**6))
    old["results"] = results
    old.setdefault("machine", _machine())
    old["issue26_created_unix"] = time.time()
    tmp = out_path.with_suffix(".tmp")
    tmp.write_text(json.dumps(old, indent=2) + "\n")
    os.replace(tmp, out_path)
    print(f"-> {out_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
