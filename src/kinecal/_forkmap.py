"""A map over forked worker processes that a Ctrl-C stops whole.

:func:`kinecal._parallel.parallel_map` ran its workers in ``concurrent.futures``'
ProcessPoolExecutor. On a Ctrl-C (a terminal sends it to every process of the command) the
command exited, but its workers stayed behind for ever, each blocked on the queues they
all share (a forked worker holds the others' pipe ends); stopping them instead
(``terminate``) can cut a result in the middle of its pipe, and the executor then waits
for the rest of it for ever. Here every worker has a pipe of its own for its tasks and one
for its results, and the parent holds no thread: stopping is killing the workers and
reaping them, whatever state they are in.

Each worker is forked with the items in its memory; the parent sends it the index of the
next item whenever it has answered, so a slow item does not hold the others back. Results
(or the item's exception) come back pickled, length-prefixed.
"""

from __future__ import annotations

import os
import pickle
import struct
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

__all__ = ["fork_map"]

T = TypeVar("T")
R = TypeVar("R")

_INDEX = struct.Struct("<q")  # a task: the item's index (-1: stop)
_HEAD = struct.Struct("<qQ")  # a result: the item's index, the pickle's length


class _Worker:
    """A forked worker: its pid, the parent's ends of its pipes, what it has sent."""

    def __init__(self, pid: int, tasks: int, results: int) -> None:
        self.pid, self.tasks, self.results = pid, tasks, results
        self.buffer = bytearray()

    def send(self, index: int) -> None:
        os.write(self.tasks, _INDEX.pack(index))

    def answers(self, chunk: bytes) -> Iterator[tuple[int, bytes]]:
        """The whole results in the bytes received so far (kept until complete)."""
        self.buffer += chunk
        while len(self.buffer) >= _HEAD.size:
            index, size = _HEAD.unpack_from(self.buffer)
            end = _HEAD.size + size
            if len(self.buffer) < end:
                return
            yield index, bytes(self.buffer[_HEAD.size : end])
            del self.buffer[:end]


def fork_map(
    fn: Callable[[T], R],
    items: Sequence[T],
    workers: int,
    initializer: Callable[[], None],
    held: Callable[[], Any],
) -> list[R]:
    """``[fn(x) for x in items]`` on ``workers`` forked processes (POSIX), in order.

    ``initializer`` runs first in each worker; ``held()`` is a context that holds
    Ctrl-C and SIGTERM while the workers are forked (:func:`kinecal._parallel`). An
    exception of ``fn`` is raised here (the first one met); on any exception, Ctrl-C
    included, every worker is killed and reaped before it propagates.
    """
    import selectors

    out: list[Any] = [None] * len(items)
    pool: dict[int, _Worker] = {}
    sel = selectors.DefaultSelector()
    try:
        with held():
            for _ in range(workers):
                w = _fork(fn, items, initializer, pool.values())
                pool[w.results] = w
        todo = iter(range(len(items)))

        def give(w: _Worker) -> None:
            """Its next item, or -1: it ends (and its pipe with it)."""
            index = next(todo, -1)
            w.send(index)
            if index < 0:
                sel.unregister(w.results)

        for w in pool.values():
            sel.register(w.results, selectors.EVENT_READ)
            give(w)
        left = len(items)
        while left:
            for key, _ in sel.select():
                w = pool[int(key.fd)]
                chunk = os.read(w.results, 1 << 20)
                if not chunk:
                    raise RuntimeError(
                        f"a worker process (pid {w.pid}) ended without its result "
                        "(killed, or out of memory?)"
                    )
                for index, data in w.answers(chunk):
                    ok, value = pickle.loads(data)
                    if not ok:
                        raise value
                    out[index] = value
                    left -= 1
                    give(w)
        return out
    except BaseException:
        import signal

        for w in pool.values():
            try:
                os.kill(w.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        raise
    finally:
        sel.close()
        for w in pool.values():
            for fd in (w.tasks, w.results):
                os.close(fd)
            try:
                os.waitpid(w.pid, 0)
            except ChildProcessError:  # reaped already (SIGCHLD ignored by the caller)
                pass


def _fork(
    fn: Callable[[T], R],
    items: Sequence[T],
    initializer: Callable[[], None],
    others: Any,
) -> _Worker:
    """Fork a worker (it never returns into the caller's code)."""
    task_r, task_w = os.pipe()
    res_r, res_w = os.pipe()
    try:
        pid = os.fork()
    except BaseException:
        for fd in (task_r, task_w, res_r, res_w):
            os.close(fd)
        raise
    if pid:
        os.close(task_r)
        os.close(res_w)
        return _Worker(pid, task_w, res_r)
    code = 1
    try:
        os.close(task_w)
        os.close(res_r)
        for w in others:  # the parent's ends of the workers forked before
            os.close(w.tasks)
            os.close(w.results)
        initializer()
        _serve(fn, items, task_r, res_w)
        code = 0
    finally:
        os._exit(code)  # never the parent's clean-up, atexit or buffered output


def _serve(fn: Callable[[T], R], items: Sequence[T], tasks: int, results: int) -> None:
    """Run the items whose indices come on ``tasks`` until -1 or the pipe's end."""
    while True:
        raw = _read(tasks, _INDEX.size)
        if len(raw) < _INDEX.size:
            return
        (index,) = _INDEX.unpack(raw)
        if index < 0:
            return
        try:
            answer: tuple[bool, Any] = (True, fn(items[index]))
        except Exception as exc:  # handed to the parent, raised there
            answer = (False, exc)
        try:
            data = pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:
            what = "result" if answer[0] else f"exception ({answer[1]!r})"
            err = RuntimeError(f"the worker's {what} cannot be sent back: {exc}")
            data = pickle.dumps((False, err))
        _write(results, _HEAD.pack(index, len(data)) + data)


def _read(fd: int, size: int) -> bytes:
    buf = b""
    while len(buf) < size:
        chunk = os.read(fd, size - len(buf))
        if not chunk:
            break
        buf += chunk
    return buf


def _write(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]
