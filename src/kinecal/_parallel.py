"""Independent runs (cross-validation folds, candidate models) on several cores.

A calibration is a chain of small numpy operations that holds the interpreter, so threads
do not overlap; worker processes do. They are forked (Linux and other POSIX systems
except macOS, whose system libraries are not fork-safe), so they start at once with
everything the parent has imported and set (:func:`kinecal.keep_freed_memory`). Elsewhere
the runs stay serial.

BLAS threads: kinecal's matrices are small (a 7000-pose Jacobian is 21000 x 50), and a
multi-threaded BLAS gains nothing on them (measured on a 2-core VM: ``J^T J`` of a
20000 x 50 matrix took 2.4 ms on one thread and 4.8 ms on two; a 7000-pose calibration the
same time). With
worker processes on every core it oversubscribes them: 20 fold calibrations on 2 workers
took 0.66x the serial time with two BLAS threads each, and ran 2.2x faster with one. So
every worker sets the OpenBLAS libraries it has loaded (numpy's and scipy's, as the PyPI
wheels ship them, and any other BLAS threadpoolctl knows) to one thread, and the ``kinecal``
command asks for one BLAS thread from the start (:func:`single_thread_blas`). In a library
user's process the entry points limit the threads themselves while they run
(:class:`kinecal._blas.one_blas_thread`).

The CPU count (:func:`available_cpus`) and the compiled model kernel's thread setting live
in :mod:`kinecal._cpu`, below both this module and :mod:`kinecal.models`.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import TypeVar

from kinecal._blas import (
    blas_threads,
    one_blas_thread,
    pin_at_start,
    set_blas_threads,
)
from kinecal._cpu import available_cpus, set_kernel_threads

# The worker processes (kinecal._forkmap) and concurrent.futures' thread pool are imported
# where used: the kinecal command imports this module at start (single_thread_blas).

__all__ = [
    "available_cpus",
    "blas_threads",
    "one_blas_thread",
    "parallel_map",
    "set_blas_threads",
    "single_thread_blas",
    "thread_map",
]

T = TypeVar("T")
R = TypeVar("R")

# Thread-count variables of the BLAS builds numpy and scipy ship with or link to.
_BLAS_THREAD_VARS = (
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "BLIS_NUM_THREADS",
)


def single_thread_blas() -> bool:
    """Ask the BLAS library for one thread, unless the user's environment already says.

    Takes effect only before numpy is first imported (BLAS reads the variables when it
    loads); returns whether it was in time. A variable set but empty says nothing (BLAS
    reads it as unset and starts a thread per core): it is set to one as well.
    """
    if "numpy" in sys.modules:
        return False
    for var in _BLAS_THREAD_VARS:
        if not os.environ.get(var, "").strip():
            os.environ[var] = "1"
    if all(os.environ[var] == "1" for var in _BLAS_THREAD_VARS):
        pin_at_start()  # the library's own limit (one_blas_thread) has nothing to do
    return True


def _one_blas_thread() -> None:
    """Worker initializer: one thread for every loaded BLAS and for the compiled
    model kernel (the workers already use every core). Ctrl-C is the parent's to
    handle (a terminal sends it to every process of the command: each worker printed its
    own traceback), and SIGTERM ends a worker at once (it inherited the command's
    handler, which unwinds the parent's staged outputs)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    # Both were blocked while the parent forked it (see parallel_map).
    signal.pthread_sigmask(signal.SIG_UNBLOCK, (signal.SIGINT, signal.SIGTERM))
    set_blas_threads(1)
    set_kernel_threads(1)


def _can_fork() -> bool:
    return sys.platform != "darwin" and hasattr(os, "fork")


def parallel_map(fn: Callable[[T], R], items: Iterable[T], jobs: int = 1) -> list[R]:
    """``[fn(x) for x in items]``, on up to ``jobs`` forked worker processes
    (:func:`kinecal._forkmap.fork_map`).

    Results come back in the order of ``items`` and are the same as the serial ones (each
    run is deterministic). The results must be picklable (the items and ``fn`` are in
    the forked workers' memory); an exception in ``fn`` is raised here. Serial when
    ``jobs <= 1``, for a single item, or where processes cannot be forked. A Ctrl-C or
    an error stops every worker before it propagates.
    """
    todo = list(items)
    workers = min(int(jobs), len(todo))
    if workers <= 1 or not _can_fork():
        return [fn(x) for x in todo]
    from kinecal._forkmap import fork_map

    return fork_map(fn, todo, workers, _one_blas_thread, _signals_held)


@contextmanager
def _signals_held() -> Iterator[None]:
    """Ctrl-C and SIGTERM wait until the block has run, then act as they would have.

    For forks: a signal handled during a fork runs its handler in the parent's at-fork
    hooks (logging's), where Python drops the handler's exception, so that Ctrl-C was
    lost and the run went on to write its result. Meanwhile the signals are recorded
    (any thread may take them) and blocked in this thread, so that a child forked here
    starts with them pending, not handled (its initializer sets what they do there).
    """
    import signal
    import threading

    stop = (signal.SIGINT, signal.SIGTERM)
    if threading.current_thread() is not threading.main_thread():
        yield  # only the main thread handles signals (and may set handlers)
        return
    came: list[int] = []
    old = {sig: signal.signal(sig, lambda sig, frame: came.append(sig)) for sig in stop}
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, stop)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # pending ones are recorded
        for sig, handler in old.items():
            signal.signal(sig, handler)
    for num in dict.fromkeys(came):  # once each, in the order they came
        handler = old[signal.Signals(num)]
        if callable(handler):
            handler(num, None)  # raises KeyboardInterrupt or the command's Terminated
        elif handler == signal.SIG_DFL:
            os.kill(os.getpid(), num)


def thread_map(fn: Callable[[T], R], items: Iterable[T], jobs: int = 0) -> list[R]:
    """``[fn(x) for x in items]`` on up to ``jobs`` threads (0: one per CPU), in order.

    For work that releases the interpreter: OpenCV calls, and numpy and scipy operations
    on large arrays (images). An exception in ``fn`` is raised here.
    """
    todo = list(items)
    workers = min(jobs if jobs > 0 else available_cpus(), len(todo))
    if workers <= 1:
        return [fn(x) for x in todo]
    from concurrent.futures import ThreadPoolExecutor

    pool = ThreadPoolExecutor(workers)
    try:
        return list(pool.map(fn, todo))
    finally:  # on an error or Ctrl-C the items not started are dropped, not run
        pool.shutdown(wait=True, cancel_futures=True)
