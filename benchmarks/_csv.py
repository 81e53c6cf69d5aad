"""CSV benchmarks (issue 26.3): reading and writing measurement files of 1e5 and 1e6 rows.

Pose data (six joints, position, quaternion: 13 columns, about 140 bytes a row), written by
``measurements_to_csv`` and read back by ``read_measurements`` (every check included).
Each case runs in a fresh process, so its peak resident memory is its own; the memory
the process held before the case (interpreter, numpy, the data) is reported beside it.
Row by row (before issue 26), on the same 2-core machine under load: 1e6 rows written
in 14.5 s (730 MB peak), read in 18.7 s (1455 MB peak); column-wise 2.8 s and 5.8 s
(724 and 639 MB), the written file byte-identical.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

_CHILD = r"""
import json, resource, sys, time, warnings
import numpy as np
from kinecal.geometry import rpy_to_matrix
from kinecal.identification import Measurements
from kinecal.io import measurements_to_csv, read_measurements
from kinecal.robot import load_robot

mode, n, path = sys.argv[1], int(sys.argv[2]), sys.argv[3]
robot = load_robot("fanuc-lrmate200id")
if mode == "write":
    rng = np.random.default_rng(0)
    lim = robot.limits * 0.9
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 6))
    meas = Measurements(
        "pose", q, rng.uniform(-0.8, 0.8, (n, 3)),
        R_user_cam=rpy_to_matrix(rng.uniform(-3, 3, (n, 3))),
    )
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
t = time.perf_counter()
if mode == "write":
    with open(path, "w") as f:
        f.write(measurements_to_csv(meas, robot))
else:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        meas = read_measurements(path, robot)
    assert meas.n == n
seconds = time.perf_counter() - t
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"seconds": seconds, "peak_rss_mb": peak, "rss_before_mb": before}))
"""


def _child(mode: str, n: int, path: Path) -> dict[str, float]:
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, mode, str(n), str(path)],
        check=True,
        capture_output=True,
        text=True,
    )
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def csv_cases(record: Callable[..., None], repeat: int) -> None:
    """Record ``csv_write_<n>`` and ``csv_read_<n>`` with ``record(name, seconds, target,
    **extra)``: the median of ``repeat`` runs, each in its own process."""
    with tempfile.TemporaryDirectory() as tmp:
        for n in (100_000, 1_000_000):
            path = Path(tmp) / f"pose_{n}.csv"
            for mode in ("write", "read"):
                runs = [_child(mode, n, path) for _ in range(repeat)]
                t = statistics.median(r["seconds"] for r in runs)
                extra: dict[str, Any] = {
                    "rows": n,
                    "us_per_row": t / n * 1e6,
                    "peak_rss_mb": max(r["peak_rss_mb"] for r in runs),
                    "rss_before_mb": max(r["rss_before_mb"] for r in runs),
                    "file_mb": path.stat().st_size / 2**20,
                }
                target = "<= 3 us per row" if mode == "write" else "<= 6 us per row"
                record(f"csv_{mode}_{n}", t, target, **extra)
