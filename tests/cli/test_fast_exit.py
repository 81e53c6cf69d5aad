"""The ``kinecal`` program leaves without tearing the interpreter down (issue 36), and
loses nothing by it: its output, exit code and files are those of :func:`kinecal.cli.main`."""

from __future__ import annotations

import subprocess
import sys
import threading

import pytest

from kinecal import _entry


class _Left(Exception):
    def __init__(self, code: int) -> None:
        self.code = code


@pytest.fixture
def os_exit(monkeypatch):
    def fake(code: int) -> None:
        raise _Left(code)

    monkeypatch.setattr(_entry.os, "_exit", fake)
    monkeypatch.delenv("KINECAL_FULL_EXIT", raising=False)


def test_leave_exits_at_once_with_the_code(os_exit):
    with pytest.raises(_Left) as left:
        _entry.leave(4)
    assert left.value.code == 4


def test_leave_exits_normally_while_another_thread_runs(os_exit):
    stop = threading.Event()
    worker = threading.Thread(target=stop.wait)  # not a daemon: the exit waits for it
    worker.start()
    try:
        with pytest.raises(SystemExit) as exited:
            _entry.leave(2)
        assert exited.value.code == 2
    finally:
        stop.set()
        worker.join()


def test_leave_ignores_daemon_threads(os_exit):
    stop = threading.Event()
    worker = threading.Thread(target=stop.wait, daemon=True)
    worker.start()
    try:
        with pytest.raises(_Left):
            _entry.leave(0)
    finally:
        stop.set()


def test_leave_exits_normally_when_asked(os_exit, monkeypatch):
    monkeypatch.setenv("KINECAL_FULL_EXIT", "1")
    with pytest.raises(SystemExit) as exited:
        _entry.leave(0)
    assert exited.value.code == 0


def _run(*args: str, **env: str) -> subprocess.CompletedProcess[str]:
    import os

    return subprocess.run(
        [sys.executable, "-m", "kinecal", *args],
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        timeout=120,
    )


def test_program_output_and_codes_same_as_full_exit(tmp_path):
    # stdout is a pipe here, so block-buffered: unflushed text would be lost
    fast = _run("fk", "--robot", "fanuc-lrmate200id", "0", "10", "20", "0", "30", "0")
    full = _run(
        "fk",
        "--robot",
        "fanuc-lrmate200id",
        "0",
        "10",
        "20",
        "0",
        "30",
        "0",
        KINECAL_FULL_EXIT="1",
    )
    assert fast.returncode == full.returncode == 0
    assert fast.stdout == full.stdout and fast.stdout.strip()
    bad = tmp_path / "bad.csv"
    bad.write_text("j1_deg,j2_deg\n1,2\n")
    refused = _run(
        "calibrate",
        str(bad),
        "--robot",
        "fanuc-lrmate200id",
        "--out",
        str(tmp_path / "o"),
    )
    assert refused.returncode == 2
    assert refused.stderr.startswith("Error: ") and "Traceback" not in refused.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("full_exit", ["", "1"])
def test_output_closed_by_its_reader_exits_141(full_exit):
    """`kinecal robots | head -0`: docs/errors.md's 141 (as SIGPIPE), with no message;
    click turned the broken pipe into exit 1 before."""
    import os

    env = {**os.environ, "KINECAL_FULL_EXIT": full_exit}
    proc = subprocess.Popen(
        [sys.executable, "-m", "kinecal", "robots"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    assert proc.stdout is not None
    proc.stdout.close()  # the reader goes away before the first line is written
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 141, err
    assert b"Traceback" not in err and b"internal error" not in err
