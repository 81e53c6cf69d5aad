"""What every benchmark module uses: timing, the process environment, the machine.

Apart from :mod:`benchmarks.__main__` so that the modules it runs import these without an
import circle (issue 32).
"""

from __future__ import annotations

import contextlib
import os
import platform
import statistics
import subprocess
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np


class Seconds(float):
    """A median wall time that also carries the best of the repeats (``.best``)."""

    best: float


def _median_time(fn: Callable[[], Any], repeat: int) -> tuple[Seconds, Any]:
    times, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    med = Seconds(statistics.median(times))
    med.best = min(times)
    return med, out


def _process_env() -> dict[str, str]:
    """Environment of the whole-process runs: Python's bytecode cache on (as installed;
    some shells set PYTHONDONTWRITEBYTECODE, which recompiles every module each run)."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


@contextlib.contextmanager
def _model_code(code: str) -> Iterator[None]:
    """Evaluate the models with ``code`` ('c' or 'numpy', KINECAL_KERNEL) inside."""
    before = os.environ.get("KINECAL_KERNEL")
    os.environ["KINECAL_KERNEL"] = code
    try:
        yield
    finally:
        if before is None:
            del os.environ["KINECAL_KERNEL"]
        else:
            os.environ["KINECAL_KERNEL"] = before


def _run(cmd: list[str]) -> None:
    subprocess.run(cmd, check=True, capture_output=True, env=_process_env())


def _machine() -> dict[str, Any]:
    info: dict[str, Any] = {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "platform": platform.platform(),
        "cpus": os.cpu_count(),
    }
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return info
