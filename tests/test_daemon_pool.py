"""The compiled kernel's worker threads (kinecal._cpu.DaemonPool): calls run and hand
back their value or exception, and a process never waits at exit for an idle or busy
worker (concurrent.futures' workers once held an interrupted command forever)."""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest

from kinecal._cpu import DaemonPool


def test_calls_return_values_and_raise_their_errors():
    pool = DaemonPool(2)
    calls = [pool.submit(pow, 2, k) for k in range(8)]
    assert [c.result() for c in calls] == [2**k for k in range(8)]
    bad = pool.submit(int, "x")
    with pytest.raises(ValueError, match="invalid literal"):
        bad.result()
    names = [
        t.name for t in threading.enumerate() if t.name.startswith("kinecal-kernel")
    ]
    assert names and all(t.daemon for t in threading.enumerate() if t.name in names)
    pool.shutdown()


def test_a_process_exits_while_a_worker_is_busy_or_idle():
    code = (
        "import time\n"
        "from kinecal._cpu import DaemonPool\n"
        "p = DaemonPool(2)\n"
        "p.submit(time.sleep, 30)\n"  # busy: the process must not wait for it
        "raise SystemExit(7)\n"
    )
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-c", code], timeout=20)
    assert r.returncode == 7
    assert time.monotonic() - t0 < 10
