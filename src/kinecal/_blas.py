"""BLAS threads: one inside kinecal's hot paths, the caller's setting restored after.

kinecal's matrices are small (a 2000-pose full-model Jacobian is 6000 x 50), and a
multi-threaded BLAS gains nothing on them; on a busy machine its threads fight for the
cores. Measured on a 2-core VM (issue 36): a Python user calling ``calibrate()`` with
OpenBLAS's default of one thread per core paid 5.9x (2000 poses) to 7.4x (20 000 poses)
the CPU time of one thread. The ``kinecal`` command asks for one thread before numpy loads
(:func:`kinecal._parallel.single_thread_blas`); a library user's process keeps whatever it
set, so the library's entry points (calibrate, evaluate, model selection,
cross-validation, bundle adjustment) run inside :class:`one_blas_thread`, which limits
every loaded BLAS to one thread and restores the previous counts when it ends.

The limits are set through threadpoolctl (every BLAS it knows: the OpenBLAS builds of
numpy and scipy, MKL, BLIS, Accelerate; Linux, macOS, Windows); where it is missing, the
OpenBLAS libraries found in ``/proc/self/maps`` are set through ctypes (Linux only).
"""

from __future__ import annotations

import sys
import threading
from contextlib import ContextDecorator
from typing import Any

__all__ = ["blas_threads", "one_blas_thread", "set_blas_threads"]

# The threadpoolctl controller (it lists the loaded libraries once, ~5 ms), kept until a
# module that loads another BLAS appears. The thread counts are the process's, not a
# thread's: the first of the (threads') nested one_blas_thread blocks sets them, the last
# to end restores them.
_controller: Any = None
_controller_key: tuple[bool, ...] | None = None
_BLAS_MODULES = ("numpy", "scipy.linalg")
_lock = threading.Lock()
_depth = 0
_before: list[int] = []
# Set by pin_at_start(): every BLAS of this process was asked for one thread before it
# loaded (the kinecal command), so one_blas_thread has nothing to do and need not even
# list the libraries (threadpoolctl's import and its listing cost ~8 ms of a command).
_pinned = False


def pin_at_start() -> None:
    """Record that every BLAS thread variable said 1 before numpy loaded."""
    global _pinned
    _pinned = True


def _blas_controller() -> Any:
    """threadpoolctl's controller of the BLAS libraries loaded now; None without it."""
    global _controller, _controller_key
    key = tuple(m in sys.modules for m in _BLAS_MODULES)
    if _controller is None or key != _controller_key:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:  # pragma: no cover - a dependency; the ctypes fallback
            return None
        _controller, _controller_key = (
            ThreadpoolController().select(user_api="blas"),
            key,
        )
    return _controller


def blas_threads() -> list[int]:
    """Threads of every loaded BLAS library (numpy's, scipy's); [] where none is found."""
    ctrl = _blas_controller()
    if ctrl is not None:
        return [int(lib.num_threads) for lib in ctrl.lib_controllers]
    return _openblas_get()  # pragma: no cover


def set_blas_threads(n: int) -> None:
    """Set every loaded BLAS library (numpy's, scipy's) to ``n`` threads."""
    global _pinned
    _pinned = _pinned and int(n) == 1
    ctrl = _blas_controller()
    if ctrl is not None:
        for lib in ctrl.lib_controllers:
            lib.set_num_threads(int(n))
        return
    _openblas_set(int(n))  # pragma: no cover


class one_blas_thread(ContextDecorator):
    """Every loaded BLAS on one thread inside (a ``with`` block or a decorator); the
    thread counts found on entry are set again on exit, also after an exception.

    Nested uses cost nothing: only the outermost one sets and restores (the counts are
    the process's: with blocks in several threads, the last to end restores them). Cheap
    otherwise too (~50 us once the loaded libraries are listed).
    """

    def __enter__(self) -> one_blas_thread:
        global _depth, _before
        with _lock:
            if _depth == 0:
                _before = [] if _pinned else blas_threads()
                if any(n != 1 for n in _before):
                    set_blas_threads(1)
            _depth += 1
        return self

    def __exit__(self, *exc: object) -> None:
        global _depth, _before
        with _lock:
            _depth -= 1
            if _depth > 0 or not any(n != 1 for n in _before):
                return
            ctrl = _blas_controller()
            libs = ctrl.lib_controllers if ctrl is not None else None
            if libs is not None and len(libs) == len(_before):
                for lib, n in zip(libs, _before):
                    lib.set_num_threads(n)
            else:  # a library loaded inside (or no threadpoolctl): the most there was
                set_blas_threads(max(_before))
            _before = []


# ---------------------------------------------------------------- ctypes fallback (Linux)
_OPENBLAS_PREFIXES = ("scipy_openblas", "openblas")
_OPENBLAS_SUFFIXES = ("64_", "")


def _openblas_functions(what: str) -> list[Any]:  # pragma: no cover - the fallback
    """``<prefix>_{what}<suffix>`` of every OpenBLAS library loaded in this process (found
    in /proc/self/maps, so Linux only); [] where there is none."""
    try:
        with open("/proc/self/maps") as fh:
            paths = sorted(
                {ln.split()[-1] for ln in fh if "openblas" in ln.lower() and "/" in ln}
            )
    except OSError:
        return []
    import ctypes

    names = [f"{p}_{what}{s}" for p in _OPENBLAS_PREFIXES for s in _OPENBLAS_SUFFIXES]
    out = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)  # the library already loaded: the same instance
        except OSError:
            continue
        fn = next((f for f in (getattr(lib, n, None) for n in names) if f), None)
        if fn is not None:
            out.append(fn)
    return out


def _openblas_get() -> list[int]:  # pragma: no cover - the fallback
    import ctypes

    out = []
    for fn in _openblas_functions("get_num_threads"):
        fn.restype = ctypes.c_int
        out.append(int(fn()))
    return out


def _openblas_set(n: int) -> None:  # pragma: no cover - the fallback
    import ctypes

    for fn in _openblas_functions("set_num_threads"):
        fn.argtypes, fn.restype = [ctypes.c_int], None
        fn(n)
