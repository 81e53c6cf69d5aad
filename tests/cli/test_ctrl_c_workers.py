"""Ctrl-C while the cross-validation runs on worker processes (``--jobs 2``).

A terminal sends Ctrl-C to every process of the command. The command said "interrupted"
and exited 130, but its workers stayed behind for ever: each blocked on the queues they
share (every worker holds the others' pipe ends), orphaned, holding the terminal's
stderr. Each also printed its own traceback (the command's SIGTERM handler, inherited),
and a Ctrl-C that came while a worker was being forked was dropped by Python (the run went
on and wrote its result with exit 0).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.helpers import live_processes

pytestmark = pytest.mark.skipif(
    not Path("/proc/self/stat").exists(), reason="reads the process table in /proc"
)


def _group(pgid: int) -> list[int]:
    """The live processes of process group ``pgid``."""
    return [pid for pid, _, group in live_processes() if group == pgid]


def _default_signals() -> None:
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_DFL)


@pytest.fixture(scope="module")
def big(tmp_path_factory):
    d = tmp_path_factory.mktemp("big")
    cmd = [sys.executable, "-m", "kinecal", "simulate", "--robot", "ur10e"]
    cmd += ["--n-train", "2500", "--n-test", "10", "--out", str(d / "sim"), "-q"]
    subprocess.run(cmd, check=True, capture_output=True)
    return d / "sim"


@pytest.mark.parametrize("after", [0.0, 0.15])
def test_ctrl_c_with_workers_ends_every_process(big, tmp_path, after):
    out = tmp_path / "cal"
    cmd = [sys.executable, "-m", "kinecal", "calibrate", str(big / "train.csv")]
    cmd += ["--robot", str(big / "robot.yaml"), "--out", str(out), "--jobs", "2"]
    p = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        preexec_fn=_default_signals,  # as a terminal gives it (see test_fault_results)
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )
    t0 = time.monotonic()
    while len(_group(p.pid)) < 3 and p.poll() is None:  # the command and two workers
        assert time.monotonic() - t0 < 120
        time.sleep(0.005)
    if p.poll() is not None:
        pytest.skip("the run ended before its workers started")
    time.sleep(after)
    os.killpg(p.pid, signal.SIGINT)
    try:
        _, err = p.communicate(timeout=60)  # EOF on stderr: no process holds it
    finally:
        for pid in _group(p.pid):  # do not leave them behind if the test fails
            os.kill(pid, signal.SIGKILL)
    t1 = time.monotonic()
    while _group(p.pid) and time.monotonic() - t1 < 10:
        time.sleep(0.05)
    assert not _group(p.pid), "worker processes outlived the command"
    assert p.returncode == 130, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert err.strip().splitlines()[-1].startswith("Error: interrupted (Ctrl-C)"), err
    assert not out.exists()
