"""Worker processes for independent runs: same results as serial, errors surface."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from kinecal._parallel import (
    available_cpus,
    blas_threads,
    parallel_map,
    set_blas_threads,
)


def _square_and_pid(x: int) -> tuple[int, int]:
    if x < 0:
        raise ValueError(f"negative: {x}")
    return x * x, os.getpid()


def test_parallel_map_keeps_order_and_uses_worker_processes():
    out = parallel_map(_square_and_pid, range(12), jobs=2)
    assert [v for v, _ in out] == [x * x for x in range(12)]
    if sys.platform.startswith("linux"):
        pids = {pid for _, pid in out}
        assert os.getpid() not in pids and 1 <= len(pids) <= 2


def test_parallel_map_serial_for_one_job():
    out = parallel_map(lambda x: (x + 1, os.getpid()), [1, 2], jobs=1)  # no pickling
    assert out == [(2, os.getpid()), (3, os.getpid())]
    assert available_cpus() >= 1


def test_an_error_in_a_worker_is_raised_with_its_type_and_message():
    with pytest.raises(ValueError, match="negative: -3"):
        parallel_map(_square_and_pid, [1, -3, 2], jobs=2)


def _python(code: str, **env: str) -> subprocess.CompletedProcess[str]:
    """``python -c CODE`` in a fresh process, OPENBLAS_NUM_THREADS unset (or ``env``)."""
    env = {
        **{k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"},
        **env,
    }
    return subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True
    )


def test_the_command_asks_for_one_blas_thread_unless_the_user_set_it():
    code = (
        "import os; from kinecal._parallel import single_thread_blas as s; "
        "ok = s(); import numpy; print(ok, os.environ['OPENBLAS_NUM_THREADS'], s())"
    )
    out = _python(code)
    assert out.stdout.split() == ["True", "1", "False"], out.stderr
    out = _python(code, OPENBLAS_NUM_THREADS="2")
    assert out.stdout.split() == ["True", "2", "False"], out.stderr
    # Set but empty: OpenBLAS reads it as unset (a thread per core).
    out = _python(code, OPENBLAS_NUM_THREADS="")
    assert out.stdout.split() == ["True", "1", "False"], out.stderr


def _threads(_: object) -> list[int]:
    return blas_threads()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_workers_run_one_blas_thread_each():
    import numpy  # noqa: F401  (loads numpy's OpenBLAS)
    import scipy.linalg  # noqa: F401  (and scipy's)

    before = blas_threads()
    assert before, "no OpenBLAS found in /proc/self/maps"
    set_blas_threads(2)  # as in a process without OPENBLAS_NUM_THREADS=1
    try:
        if set(blas_threads()) != {2}:
            pytest.skip("OpenBLAS caps its threads at 1 here")
        for threads in parallel_map(_threads, range(4), jobs=2):
            assert threads and set(threads) == {1}, threads
        assert set(blas_threads()) == {2}  # the parent keeps its own
    finally:
        set_blas_threads(before[0])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_a_kinecal_command_runs_with_one_blas_thread():
    code = (
        "from kinecal.cli import main; main(['robots']); "
        "import numpy, scipy.linalg; from kinecal._parallel import blas_threads; "
        "print('threads', *blas_threads())"
    )
    out = _python(code)
    line = [ln for ln in out.stdout.splitlines() if ln.startswith("threads")]
    assert line and set(line[0].split()[1:]) == {"1"}, out.stdout + out.stderr


def _blas_during_calibration(threads_seen: list[list[int]]) -> object:
    """A stage that records the BLAS thread counts while calibrate() runs it."""

    def stage(problem: object, state: object) -> object:
        threads_seen.append(blas_threads())
        return state

    return stage


def test_calibrate_runs_on_one_blas_thread_and_restores_the_callers_setting():
    """A library user who set 2 BLAS threads: calibrate() runs its stages on one (the
    small matrices gain nothing from more, and they fight over a busy machine), and the
    user's 2 are back afterwards, also when a stage raises."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401

    from kinecal.identification import calibrate, default_stages
    from kinecal.simulation import LaserTracker, experiment2

    before = blas_threads()
    assert before, "no BLAS library found"
    e = experiment2(0, tracker=LaserTracker(5e-6, 0.0))
    seen: list[list[int]] = []
    set_blas_threads(2)
    try:
        if set(blas_threads()) != {2}:
            pytest.skip("the BLAS caps its threads at 1 here")
        stages = (*default_stages()[:2], _blas_during_calibration(seen))
        calibrate(e.truth.robot, e.train, "kinematic", stages=stages)
        assert seen and set(seen[0]) == {1}
        assert set(blas_threads()) == {2}  # the caller's setting, restored

        def fail(problem: object, state: object) -> object:
            raise RuntimeError("a stage failed")

        with pytest.raises(RuntimeError, match="a stage failed"):
            calibrate(e.truth.robot, e.train, "kinematic", stages=(fail,))
        assert set(blas_threads()) == {2}
    finally:
        set_blas_threads(before[0])


def test_one_blas_thread_nests_and_restores_each_library():
    """Nested blocks: only the outermost sets and restores; each library gets its own
    count back (numpy's and scipy's OpenBLAS set apart here)."""
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401

    from kinecal._blas import _blas_controller, one_blas_thread

    ctrl = _blas_controller()
    if ctrl is None or len(ctrl.lib_controllers) < 1:
        pytest.skip("no BLAS found by threadpoolctl")
    libs = ctrl.lib_controllers
    before = [lib.num_threads for lib in libs]
    try:
        for k, lib in enumerate(libs):
            lib.set_num_threads(2 + k % 2)
        wanted = blas_threads()
        if wanted != [2 + k % 2 for k in range(len(libs))]:
            pytest.skip("the BLAS caps its threads here")
        with one_blas_thread():
            assert set(blas_threads()) == {1}
            with one_blas_thread():
                assert set(blas_threads()) == {1}
            assert set(blas_threads()) == {1}  # the inner block left it
        assert blas_threads() == wanted
    finally:
        for lib, n in zip(libs, before):
            lib.set_num_threads(n)


def test_an_in_process_command_runs_on_one_blas_thread(monkeypatch, capsys):
    """kinecal.cli.main called where numpy is already loaded (a test, a notebook): the
    command's environment variable comes too late, so the command runs inside
    one_blas_thread and the caller's count is back afterwards."""
    import click
    import numpy  # noqa: F401

    from kinecal.cli import main

    seen: list[list[int]] = []
    echo = click.echo

    def spy(*args: object, **kw: object) -> None:
        seen.append(blas_threads())
        echo(*args, **kw)

    before = blas_threads()
    set_blas_threads(2)
    try:
        if set(blas_threads()) != {2}:
            pytest.skip("the BLAS caps its threads at 1 here")
        monkeypatch.setattr(click, "echo", spy)
        assert main(["robots"]) == 0
        assert seen and all(set(s) == {1} for s in seen)
        assert set(blas_threads()) == {2}
    finally:
        set_blas_threads(before[0])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="OpenBLAS threads")
def test_the_command_pins_one_thread_at_start_unless_the_user_set_more():
    """Where the command asked every BLAS for one thread before numpy loaded, the
    library's limit has nothing to do (threadpoolctl is not even imported); where the
    user's environment asked for two, the limit still applies inside and restores."""
    code = (
        "import sys; from kinecal._parallel import single_thread_blas as s; s()\n"
        "import numpy, scipy.linalg\n"
        "from kinecal._blas import one_blas_thread, blas_threads\n"
        "with one_blas_thread():\n"
        "    loaded = 'threadpoolctl' in sys.modules\n"
        "    inside = blas_threads() if loaded else []\n"
        "import json; print(json.dumps([loaded, inside, blas_threads()]))"
    )
    out = _python(code)
    loaded, inside, after = _three(out)
    assert not loaded and inside == [] and after and set(after) == {1}
    out = _python(code, OPENBLAS_NUM_THREADS="2")
    loaded, inside, after = _three(out)
    if set(after) != {2}:
        pytest.skip("the BLAS caps its threads at 1 here")
    assert loaded and inside and set(inside) == {1}


def _three(out: subprocess.CompletedProcess[str]) -> list:
    import json

    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.splitlines()[-1])


def _slow_first(x: int) -> int:
    import time

    time.sleep(0.2 if x == 0 else 0.0)
    return x + 100


def _dies(x: int) -> int:
    if x == 2:
        os._exit(3)  # a worker killed (out of memory, kill -9)
    return x


def _unpicklable(x: int):
    return lambda: x


def test_workers_take_the_next_item_when_they_answer():
    """A slow item does not hold the others back, and the order is kept."""
    assert parallel_map(_slow_first, range(9), jobs=2) == [x + 100 for x in range(9)]


@pytest.mark.skipif(not hasattr(os, "fork"), reason="serial without fork")
def test_a_worker_that_dies_is_an_error_and_no_worker_is_left():
    before = _children()
    with pytest.raises(RuntimeError, match="ended without its result"):
        parallel_map(_dies, range(6), jobs=2)
    assert _children() == before
    with pytest.raises(RuntimeError, match="cannot be sent back"):
        parallel_map(_unpicklable, range(3), jobs=2)
    assert _children() == before


def _children() -> set[int]:
    """This process's live child processes (Linux), else an empty set."""
    from tests.helpers import live_processes

    return {pid for pid, parent, _ in live_processes() if parent == os.getpid()}


@pytest.mark.slow  # (20 maps of forked workers: 1.5 s)
@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="counts open files")
def test_repeated_maps_leave_no_file_open():
    before = len(os.listdir("/proc/self/fd"))
    for _ in range(20):
        assert parallel_map(_slow_first, [1, 2, 3], jobs=2) == [101, 102, 103]
    assert len(os.listdir("/proc/self/fd")) == before
