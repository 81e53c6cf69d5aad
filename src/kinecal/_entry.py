"""The ``kinecal`` program: :func:`kinecal.cli.main`, then leave without tearing down.

When a command has returned, its results are written and closed (atomically, and moved
into place by the output transaction). What the interpreter would still do is free every
module and object one by one: with numpy and kinecal loaded that is ~20 ms of CPU, 7-9 %
of a 2000-pose ``kinecal calibrate`` (issue 36). :func:`run` flushes the standard streams and
ends the process with :func:`os._exit` instead, as other command-line programs in Python
do. It falls back to the normal exit where that could lose something: another thread still
running (daemon threads, such as kinecal's own workers, end with the process either
way), or ``KINECAL_FULL_EXIT`` set (coverage tools, profilers that write at exit).
``kinecal.cli.main`` itself only returns the code: a caller in Python keeps its process.

A command is also one short run for the cyclic garbage collector: by default it looks
for cycles every 700 new objects, and the ~40 000 that the imports create (functions,
classes, dictionaries, alive to the end) made that calibrate run ~60 collections, ~10 ms
(3 %) that found nothing to free. :func:`run` lets :data:`GC_YOUNG` new objects come
first: a command of a few thousand poses collects none, a longer run collects its cycles
every GC_YOUNG objects. Again for the program only: ``main`` keeps the caller's setting.
So is the cache of compiled dataclass methods (:mod:`kinecal._codecache`: 17-19 ms of a
calibrate run compiled the same texts every time), written before leaving.
"""

from __future__ import annotations

import gc
import os
import sys
import threading
from typing import NoReturn

from kinecal import _codecache

__all__ = ["run"]

# New container objects between two collections of the youngest generation (Python's
# default: 700), for the ``kinecal`` program.
GC_YOUNG = 100_000


def run() -> NoReturn:
    """Entry point of the ``kinecal`` console script and of ``python -m kinecal``."""
    gc.set_threshold(GC_YOUNG, *gc.get_threshold()[1:])
    _codecache.install()
    from kinecal.cli import main

    code = main()
    leave(code)


def leave(code: int) -> NoReturn:
    """End the process with ``code``: at once after flushing the standard streams (and
    logging's handlers, if logging was used), or normally where that is safer."""
    _codecache.save()
    if os.environ.get("KINECAL_FULL_EXIT") or _other_threads():
        sys.exit(code)
    for stream in (sys.stdout, sys.stderr):
        try:
            if stream is not None:
                stream.flush()
        except (OSError, ValueError):  # a closed pipe: nothing more can reach it
            pass
    logging = sys.modules.get("logging")
    if logging is not None:
        logging.shutdown()
    os._exit(code)


def _other_threads() -> bool:
    """Is a thread other than the main one running that the interpreter would wait for?"""
    main = threading.main_thread()
    return any(
        t is not main and t.is_alive() and not t.daemon for t in threading.enumerate()
    )
