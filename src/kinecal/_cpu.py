"""CPUs this process may use, and how many threads one compiled-kernel evaluation takes.

The bottom of the package's import graph, with :mod:`kinecal.errors` and
:mod:`kinecal.typing`: it imports nothing of kinecal, so that both the worker processes of
:mod:`kinecal._parallel` (which set one kernel thread each) and the compiled model kernel
(:mod:`kinecal.models._kernel`, which splits large batches over threads) can use it
without importing one another.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import queue

__all__ = [
    "DaemonPool",
    "available_cpus",
    "kernel_threads",
    "set_kernel_threads",
]

# Threads one kernel evaluation may use: None for one per CPU (counted once, on first use).
_threads: int | None = None
_cpus: int | None = None


def available_cpus() -> int:
    """CPUs this process may use: its affinity mask where the OS has one, capped by a
    cgroup (v2) CPU quota, as a container's ``--cpus`` sets it."""
    try:
        n = len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - macOS, Windows
        n = os.cpu_count() or 1
    quota = _cgroup_cpu_quota(Path("/sys/fs/cgroup/cpu.max"))
    return max(1, min(n, quota)) if quota is not None else n


def _cgroup_cpu_quota(path: Path) -> int | None:
    """CPUs allowed by a cgroup v2 ``cpu.max`` file (``"QUOTA PERIOD"`` in us, or
    ``"max PERIOD"`` for none), rounded up; None where there is no limit or no file."""
    try:
        fields = path.read_text().split()
    except OSError:
        return None
    if len(fields) != 2 or fields[0] == "max":
        return None
    try:
        quota, period = int(fields[0]), int(fields[1])
    except ValueError:
        return None
    return -(-quota // period) if quota > 0 and period > 0 else None


def set_kernel_threads(count: int | None) -> None:
    """Threads the compiled kernel may split one evaluation over (None: one per CPU)."""
    global _threads
    if count is not None and count < 1:
        raise ValueError(f"count must be >= 1 or None; got {count}.")
    _threads = count


def kernel_threads() -> int:
    """Most threads one kernel evaluation may use: the count of
    :func:`set_kernel_threads`, else :func:`available_cpus` (counted on the first call)."""
    global _cpus
    if _threads is not None:
        return _threads
    if _cpus is None:
        _cpus = available_cpus()
    return _cpus


class DaemonPool:
    """Worker threads for the compiled kernel that never hold up the interpreter's exit.

    concurrent.futures' workers are joined when the interpreter exits; after a Ctrl-C a
    worker was once left waiting on its queue, unwoken, and the interrupted command hung
    at exit (an interrupted-calibration test, the suite run as a background job). These
    are daemon threads taking calls from a queue; a caller waits for its own calls
    (:meth:`Call.result`), so none is in flight when a command ends normally.
    """

    def __init__(self, size: int, name: str = "kinecal-kernel") -> None:
        import queue  # here: a command on one thread starts no pool (heapq with it)

        self.size = size
        self._queue: queue.SimpleQueue[Call | None] = queue.SimpleQueue()
        for i in range(size):
            threading.Thread(target=self._work, name=f"{name}-{i}", daemon=True).start()

    def submit(self, fn: Callable[..., Any], *args: Any) -> Call:
        """Run ``fn(*args)`` on a worker."""
        call = Call(fn, args)
        self._queue.put(call)
        return call

    def shutdown(self) -> None:
        """Let the workers end once the calls already submitted are done."""
        for _ in range(self.size):
            self._queue.put(None)

    def _work(self) -> None:
        while (call := self._queue.get()) is not None:
            call.run()


class Call:
    """A call submitted to a :class:`DaemonPool`."""

    def __init__(self, fn: Callable[..., Any], args: tuple[Any, ...]) -> None:
        self._fn, self._args = fn, args
        self._done = threading.Event()
        self._value: Any = None
        self._error: BaseException | None = None

    def run(self) -> None:
        try:
            self._value = self._fn(*self._args)
        except BaseException as exc:  # handed to the caller
            self._error = exc
        finally:
            self._done.set()

    def result(self) -> Any:
        """The call's value, once it has run (its exception raised here)."""
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._value
