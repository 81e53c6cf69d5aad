"""The command's one error path: exit codes and the one-line message of every failure.

Every failure ends in one line on stderr, ``Error: <file or option>: <what>; <expected
or what to do>``, and one of the exit codes of :class:`ExitCode` (docs/errors.md lists
them with the messages a user can meet). Nothing prints a traceback unless
``KINECAL_DEBUG=1`` is set.
"""

from __future__ import annotations

import errno
import os
import signal
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from enum import IntEnum
from typing import Any

import click

__all__ = [
    "CommandFailed",
    "ExitCode",
    "classify",
    "handled_signals",
    "one_line_warnings",
]


class ExitCode(IntEnum):
    """Exit codes of the ``kinecal`` command (one place; docs/errors.md explains them)."""

    OK = 0
    INTERNAL = 1  # a defect in kinecal: please report it
    BAD_INPUT = 2  # a file, option or data set the command cannot use
    NOT_CONVERGED = 3  # the calibration did not converge (results still written)
    UNREACHABLE = 4  # compensate: some targets cannot be reached
    IO = 5  # the system refused: permission, read-only or full disk, no memory
    BROKEN_PIPE = 141  # the reader of the output went away (`| head`), as SIGPIPE
    TERMINATED = 143  # SIGTERM
    INTERRUPTED = 130  # Ctrl-C (SIGINT)


# Committing result folders: these codes mean the command's results are valid.
RESULT_CODES = (ExitCode.OK, ExitCode.NOT_CONVERGED)

_PATH_MISTAKE_TYPES = (
    FileNotFoundError,
    FileExistsError,
    IsADirectoryError,
    NotADirectoryError,
)
_PATH_MISTAKE_ERRNOS = {
    errno.ENOENT,
    errno.EEXIST,
    errno.EISDIR,
    errno.ENOTDIR,
    errno.ENAMETOOLONG,
    errno.ELOOP,
}
_OS_TEXT = {
    errno.ENOENT: "no such file or folder; check the path",
    errno.EEXIST: "exists; use --force to replace it",
    errno.EISDIR: "is a folder; expected a file",
    errno.ENOTDIR: "a part of the path is not a folder; check the path",
    errno.ENAMETOOLONG: "file name too long; use a shorter path",
    errno.ELOOP: "too many symbolic links; check the path",
    errno.EACCES: "permission denied; expected a file or folder you may read and "
    "write (check its permissions, or choose another place)",
    errno.EPERM: "operation not permitted; expected a file or folder you may read "
    "and write (check its permissions, or choose another place)",
    errno.EROFS: "read-only file system; write the results to a writable place",
    errno.ENOSPC: "no space left on the device; free some space or write the results "
    "elsewhere (nothing was half-written)",
    errno.EDQUOT: "disk quota exceeded; free some space or write the results elsewhere",
    errno.EFBIG: "file too large for the file system; write the results elsewhere",
    errno.EMFILE: "too many open files; raise the limit (ulimit -n)",
    errno.ENFILE: "too many open files in the system; try again later",
    errno.EIO: "input/output error (a failing disk or network drive); check the device",
}


class CommandFailed(Exception):
    """A command's own failure with its exit code (compensate's unreachable targets)."""

    def __init__(self, code: ExitCode, message: str) -> None:
        super().__init__(message)
        self.code = code


class ResultsWithError(SystemExit):
    """Exit with ``code`` (a result code: the results are committed) and ``message`` as
    the final ``Error:`` line, printed after them (a calibration that did not
    converge: exit 3)."""

    def __init__(self, code: ExitCode, message: str) -> None:
        super().__init__(int(code))
        self.message = message


class Terminated(BaseException):
    """SIGTERM, turned into an exception so that staged results are removed."""


def one_line(text: str) -> str:
    """``text`` on one line (line breaks and runs of blanks become one blank), a staged
    result folder in it named as the user knows it."""
    from kinecal._outputs import user_paths_in

    return user_paths_in(" ".join(str(text).split()))


def _os_error(exc: OSError) -> tuple[ExitCode, str]:
    mistake = isinstance(exc, _PATH_MISTAKE_TYPES) or exc.errno in _PATH_MISTAKE_ERRNOS
    code = ExitCode.BAD_INPUT if mistake else ExitCode.IO
    if exc.errno is None:  # a message of kinecal's own
        return code, one_line(str(exc) or type(exc).__name__)
    what = _OS_TEXT.get(exc.errno) or f"{exc.strerror or 'system error'}"
    if exc.filename is None:
        return code, what
    from kinecal._outputs import user_path

    return code, f"{user_path(os.fsdecode(exc.filename))}: {what}"


def classify(exc: BaseException) -> tuple[ExitCode, str]:
    """Exit code and one-line message (without "Error: ") of an exception that ended a
    command."""
    from kinecal.errors import CalibError, OutputClosed

    if isinstance(exc, CommandFailed):
        return exc.code, one_line(str(exc))
    if isinstance(exc, CalibError):
        return ExitCode.BAD_INPUT, one_line(str(exc))
    if isinstance(exc, click.UsageError):
        hint = ""
        if exc.ctx is not None:
            hint = f" (see '{exc.ctx.command_path} --help')"
        return ExitCode.BAD_INPUT, one_line(exc.format_message()).rstrip(".") + hint
    if isinstance(exc, click.ClickException):
        return ExitCode.BAD_INPUT, one_line(exc.format_message())
    if isinstance(exc, (KeyboardInterrupt, click.exceptions.Abort)):
        return ExitCode.INTERRUPTED, (
            "interrupted (Ctrl-C); nothing of this run was written, earlier results are "
            "unchanged"
        )
    if isinstance(exc, Terminated):
        return ExitCode.TERMINATED, (
            "terminated (SIGTERM); nothing of this run was written, earlier results are "
            "unchanged"
        )
    if isinstance(exc, (BrokenPipeError, OutputClosed)):
        return ExitCode.BROKEN_PIPE, "the output was closed by its reader"
    if isinstance(exc, OSError):
        return _os_error(exc)
    if isinstance(exc, MemoryError):
        return ExitCode.IO, (
            "out of memory; use a smaller data set or a machine with more memory"
        )
    return ExitCode.INTERNAL, _internal(exc)


def _internal(exc: BaseException) -> str:
    from kinecal._version import __version__

    tb = traceback.extract_tb(exc.__traceback__)
    where = ""
    if tb:
        f = tb[-1]
        where = f" at {os.path.basename(f.filename)}:{f.lineno}"
    what = one_line(f"{type(exc).__name__}: {exc}")
    if len(what) > 300:
        what = what[:297] + "..."
    return (
        f"internal error ({what}{where}, kinecal {__version__}); this is a defect in "
        "kinecal: please report it with the command line (KINECAL_DEBUG=1 shows the "
        "traceback)"
    )


def debug() -> bool:
    """``KINECAL_DEBUG=1``: show tracebacks."""
    return os.environ.get("KINECAL_DEBUG", "") not in ("", "0")


@contextmanager
def one_line_warnings() -> Iterator[None]:
    """Show Python warnings as ``warning: <message>`` lines (no source line, no
    file:line) while the command runs."""
    old = warnings.showwarning

    def show(message: Any, category: Any, filename: str, lineno: int, *a: Any) -> None:
        if debug():
            old(message, category, filename, lineno, *a)
            return
        click.echo(f"warning: {one_line(str(message))}", err=True)

    warnings.showwarning = show  # type: ignore[assignment]
    try:
        yield
    finally:
        warnings.showwarning = old


@contextmanager
def handled_signals() -> Iterator[None]:
    """SIGTERM raises :class:`Terminated` (so staged results are removed, as on Ctrl-C);
    the previous handler comes back afterwards. Only in the main thread."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_term(signum: int, frame: Any) -> None:
        raise Terminated()

    old: Callable[..., Any] | int | None = signal.signal(signal.SIGTERM, on_term)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def quiet_broken_pipe() -> None:
    """After EPIPE on stdout: point stdout at /dev/null so the interpreter's final flush
    does not print another error."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
