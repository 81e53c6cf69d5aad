"""The command-line contract of issue 21, shared by the fault tests and the fuzz suite:
``kinecal`` run in-process, and what every run must keep.

Exit 0 with a valid result, or a documented non-zero exit (2 bad input, 3 not converged,
4 unreachable, 5 I/O) whose message is one ``Error:`` line; never a traceback or an
internal error (exit 1), never a half-written result folder.
"""

from __future__ import annotations

import contextlib
import os
import signal
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

DOCUMENTED = {0, 2, 3, 4, 5}
STAGING = ".kinecal-tmp-"


@dataclass
class Run:
    code: int
    out: str
    err: str

    def __str__(self) -> str:
        return f"exit {self.code}\n--- stdout\n{self.out}\n--- stderr\n{self.err}"

    def __iter__(self) -> Iterator[int | str]:
        """``code, out, err = run_kinecal(...)``."""
        return iter((self.code, self.out, self.err))


@contextlib.contextmanager
def no_hang(seconds: float) -> Iterator[None]:
    """Fail (an exception inside the command: exit 1) if the block runs longer."""

    def fire(signum, frame):
        raise TimeoutError(f"the command ran longer than {seconds} s (a hang?)")

    old = signal.signal(signal.SIGALRM, fire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def run_kinecal(capsys: pytest.CaptureFixture[str], *args: str) -> Run:
    """``kinecal ARGS`` in this process (kinecal.cli.main), with its output."""
    from kinecal.cli import main

    capsys.readouterr()
    with no_hang(60.0):
        code = main([str(a) for a in args])
    cap = capsys.readouterr()
    return Run(code, cap.out, cap.err)


def check_contract(res: Run) -> None:
    """Exit 0, or a documented code with one ``Error:`` line last; no traceback."""
    assert res.code in DOCUMENTED, str(res)
    assert "Traceback" not in res.err and "internal error" not in res.err, str(res)
    if res.code != 0:
        lines = [ln for ln in res.err.splitlines() if ln.strip()]
        assert lines and lines[-1].startswith("Error: "), str(res)
        assert sum(ln.startswith("Error:") for ln in lines) == 1, str(res)


def leftovers(folder: Path) -> list[str]:
    """Temporary entries a run left below ``folder`` (staged folders, temp files)."""
    out = []
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            if STAGING in name or name.endswith(".tmp"):
                out.append(str(Path(root) / name))
    return out


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file below ``folder`` with its bytes."""
    if not folder.exists():
        return {}
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


def make_point_data(d: Path) -> dict[str, Path]:
    """A small laser-tracker data set (40 poses), a model calibrated on it, a test set
    and compensation targets, written by kinecal itself."""
    from kinecal.identification import calibrate
    from kinecal.io import save_model, write_measurements
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=5, n_train=40)
    robot = e.truth.robot
    write_measurements(d / "train.csv", e.train, robot)
    write_measurements(d / "test.csv", e.test.subset(np.arange(20)), robot)
    res = calibrate(robot, e.train, "full")
    save_model(d / "model.yaml", res.calibrated)
    p = e.test.p[:6] * 1e3  # measured tool points: reachable
    q = np.degrees(e.test.q_ctrl[:6])
    lines = ["x_mm,y_mm,z_mm," + ",".join(f"j{k + 1}_deg" for k in range(6))]
    for pp, qq in zip(p, q):
        lines.append(",".join(f"{v:.6f}" for v in (*pp, *qq)))
    (d / "targets.csv").write_text("\n".join(lines) + "\n")
    return {
        "dir": d,
        "train": d / "train.csv",
        "test": d / "test.csv",
        "model": d / "model.yaml",
        "targets": d / "targets.csv",
    }


def failed_with(res: Run, *needles: str, code: int = 2) -> str:
    """The run failed with ``code`` and one Error line holding every needle; that line."""
    check_contract(res)
    assert res.code == code, str(res)
    last = res.err.strip().splitlines()[-1]
    for n in needles:
        assert n in last, str(res)
    return last
