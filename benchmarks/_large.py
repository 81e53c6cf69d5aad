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


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
