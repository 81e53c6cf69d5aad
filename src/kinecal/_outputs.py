"""Result folders that never lie: staged beside (or inside) ``--out``, moved into place
at the end.

A command that writes a folder of results (``calibrate --out DIR``: model.yaml,
report.json, residuals.csv, manifest.json, report.html) writes them all into a temporary
folder first. Only when the command has succeeded are they moved into DIR:

* DIR does not exist yet: the temporary folder ``.DIR.kinecal-tmp-*`` beside it is
  renamed to DIR, one atomic step.
* DIR exists: the temporary folder is ``DIR/.kinecal-tmp-*``; its entries are renamed into
  DIR (each rename atomic, the manifest last) while Ctrl-C and SIGTERM wait. With
  ``force`` the earlier result is replaced as a whole: every entry it consisted of (the
  command's names and the files its manifest.json lists) that the new result does not
  have is removed, so no report.html of an earlier run stays beside a new model.yaml.
  Other files in DIR (the user's own) are left alone.

A failure, Ctrl-C or a crash before that leaves DIR as it was (the previous result or
nothing); the temporary folder is removed, or, after a hard kill, swept by the next run
that writes beside it.

This module is light (standard library only): the ``kinecal`` command opens its
transaction before any heavy import. :mod:`kinecal.io` re-exports it.
"""

from __future__ import annotations

import fnmatch
import os
import re
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from kinecal._record import MutableRecord

__all__ = [
    "OutputTransaction",
    "begin_transaction",
    "clashes",
    "current_transaction",
    "end_transaction",
    "new_dir_mode",
    "new_file_mode",
    "note_input",
    "output_transaction",
    "refuse_input",
    "signals_held",
    "user_path",
    "user_paths_in",
]

_TAG = ".kinecal-tmp-"
_UMASK: int | None = None
_UMASK_LOCK = threading.Lock()


def user_path(name: str) -> str:
    """The path a user knows for a temporary one of kinecal's: a staged result folder
    (``DIR/.kinecal-tmp-*/f`` or ``.DIR.kinecal-tmp-*/f`` -> ``DIR/f``) or the temporary
    file of an atomic write (``.f.abcd1234.tmp`` -> ``f``)."""
    parts = name.split("/")
    out = []
    for i, part in enumerate(parts):
        if part.startswith(_TAG):
            continue
        m = re.fullmatch(r"\.(.+)\.kinecal-tmp-.*", part)
        if m:
            part = m.group(1)
        elif i == len(parts) - 1:
            m = re.fullmatch(r"\.(.+)\.[A-Za-z0-9_]{8}\.tmp", part)
            part = m.group(1) if m else part
        out.append(part)
    return "/".join(out)


def user_paths_in(text: str) -> str:
    """``text`` with every staged result folder in it named as the user knows it
    (``DIR/.kinecal-tmp-*/f`` and ``.DIR.kinecal-tmp-*/f`` -> ``DIR/f``)."""
    text = re.sub(r"/\.kinecal-tmp-[\w-]+(?=/)", "", text)
    return re.sub(r"(^|[/\s'\"(])\.([^/\s]+?)\.kinecal-tmp-[\w-]+(?=/)", r"\1\2", text)


def _umask() -> int:
    """The process's umask (read once: Linux reports it in /proc, elsewhere it is set and
    put back, which is why it is read only once)."""
    global _UMASK
    with _UMASK_LOCK:
        if _UMASK is None:
            try:
                with open("/proc/self/status", encoding="ascii") as f:
                    line = next(ln for ln in f if ln.startswith("Umask:"))
                _UMASK = int(line.split()[1], 8)
            except (OSError, StopIteration, ValueError, IndexError):
                _UMASK = os.umask(0o022)
                os.umask(_UMASK)
        return _UMASK


def new_file_mode() -> int:
    """Mode of a new file under the user's umask (``0o666 & ~umask``)."""
    return 0o666 & ~_umask()


def new_dir_mode() -> int:
    """Mode of a new folder under the user's umask (``0o777 & ~umask``)."""
    return 0o777 & ~_umask()


_MANIFEST = "manifest.json"
_local = threading.local()


def _stack() -> list[OutputTransaction]:
    if not hasattr(_local, "stack"):
        _local.stack = []
    return _local.stack  # type: ignore[no-any-return,unused-ignore]


def current_transaction() -> OutputTransaction | None:
    """The innermost active transaction of this thread, or None."""
    s = _stack()
    return s[-1] if s else None


def _matches(entry: str, names: list[str]) -> bool:
    """``entry`` is one of ``names`` or matches one of its patterns (a plain name is
    compared as it stands: fnmatch would compile a regular expression for it)."""
    return any(
        fnmatch.fnmatchcase(entry, n)
        if "*" in n or "?" in n or "[" in n
        else entry == n
        for n in names
    )


def clashes(folder: Path, names: list[str]) -> list[str]:
    """Entries of ``folder`` a result made of ``names`` (names or glob patterns) would
    replace, sorted."""
    if not folder.is_dir():
        return []
    return sorted(
        e for e in os.listdir(folder) if not e.startswith(".") and _matches(e, names)
    )


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _sweep(folder: Path) -> None:
    """Remove temporary folders that a killed kinecal run left in ``folder``."""
    try:
        entries = os.listdir(folder)
    except OSError:
        return
    for e in entries:
        if _TAG not in e:
            continue
        try:
            pid = int(e.split(_TAG, 1)[1].split("-", 1)[0])
        except ValueError:
            continue
        if pid != os.getpid() and not _pid_alive(pid):
            _rmtree(folder / e)


def _old_result(final: Path, names: list[str]) -> set[str]:
    """Entries of ``final`` that belong to its earlier result: the command's names and
    what the earlier manifest.json lists under ``files``."""
    listed: list[str] = []
    try:
        import json

        doc = json.loads((final / _MANIFEST).read_text(encoding="utf-8"))
        files = doc.get("files") if isinstance(doc, dict) else None
        if isinstance(files, list):
            listed = [f for f in files if isinstance(f, str) and "/" not in f]
    except (OSError, ValueError, RecursionError):  # a damaged manifest lists nothing
        pass
    out = set(clashes(final, names))
    out.update(f for f in listed if f not in (".", "..") and (final / f).exists())
    return out


_HELD = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def signals_held(late: list[int]) -> Iterator[None]:
    """Hold SIGINT and SIGTERM in the main thread during the block; one that arrived
    meanwhile is taken (not delivered) and appended to ``late``."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, _HELD)
    try:
        yield
    finally:
        try:
            pending = signal.sigpending()
            for sig in _HELD:
                if sig in pending and sig not in old:
                    signal.sigwait({sig})  # pending: returns at once, consumes it
                    late.append(int(sig))
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


@dataclass(eq=False, repr=False)
class _Staged(MutableRecord):
    final: Path
    staging: Path
    names: list[str]
    force: bool
    inside: bool  # staging is inside final (final existed)


@dataclass(eq=False, repr=False)
class OutputTransaction(MutableRecord):
    """Result folders staged by :func:`prepare_output_dir`, committed or discarded as a
    whole."""

    staged: list[_Staged] = field(default_factory=list)
    # Ctrl-C or SIGTERM that came while the results were being moved into place: the
    # move completed, and the signal is reported here instead of raised.
    late_signals: list[int] = field(default_factory=list)
    # The files this command reads, by (device, inode): an output that is one of them
    # (the same name, a symbolic or a hard link) is refused, --force or not.
    inputs: dict[tuple[int, int], str] = field(default_factory=dict)

    def note_input(self, path: str | Path, what: str = "") -> None:
        """Remember ``path`` as an input (``what``: e.g. "DATA"); a path that is not an
        existing file is ignored."""
        try:
            st = os.stat(path)
        except (OSError, ValueError):
            return
        if not os.path.isdir(path):
            self.inputs.setdefault((st.st_dev, st.st_ino), what or str(path))

    def refuse_input(self, path: str | Path) -> None:
        """Raise if writing ``path`` would replace one of this command's inputs."""
        if not self.inputs:
            return
        try:
            st = os.stat(path)
        except (OSError, ValueError):
            return
        what = self.inputs.get((st.st_dev, st.st_ino))
        if what is not None:
            from kinecal.errors import DataError

            if what.endswith(f" {path}"):  # the file is named once, at the start
                what = what[: -len(str(path)) - 1]
            what = "" if what in (str(path), os.fspath(path)) else f" ({what})"
            raise DataError(
                f"{path}: is an input of this command{what}; writing the output there "
                "would replace it, so it is refused (--force or not): choose another "
                "output name."
            )

    def stage(self, final: Path, names: list[str], *, force: bool) -> Path:
        """A new temporary folder for the result ``final`` (created here)."""
        for s in self.staged:
            if s.final == final:
                return s.staging
        tag = f"{_TAG}{os.getpid()}-{os.urandom(4).hex()}"
        if final.is_dir():
            _sweep(final)
            staging, inside = final / tag, True
        else:
            parent = final.absolute().parent
            parent.mkdir(parents=True, exist_ok=True)
            _sweep(parent)
            staging, inside = parent / f".{final.absolute().name}{tag}", False
        os.mkdir(staging)
        os.chmod(staging, new_dir_mode())
        self.staged.append(_Staged(final, staging, list(names), force, inside))
        return staging

    def rollback(self) -> None:
        """Remove every staged folder; the targets stay as they were."""
        for s in self.staged:
            _rmtree(s.staging)
        self.staged.clear()

    def commit(self) -> list[Path]:
        """Move every staged result into place; return the result folders."""
        done = []
        with signals_held(self.late_signals):
            try:
                for s in self.staged:
                    _commit(s)
                    done.append(s.final)
            finally:
                self.rollback()  # what was not moved (after a failure), the trash
        return done


def _commit(s: _Staged) -> None:
    if not s.inside:
        try:
            os.rename(s.staging, s.final)  # atomic; fails if final appeared meanwhile
            return
        except OSError:
            if not s.final.is_dir():
                raise
            # Someone created the folder meanwhile: merge into it like an existing one.
            inner = s.final / s.staging.name
            os.rename(s.staging, inner)
            s.staging, s.inside = inner, True
    entries = sorted(os.listdir(s.staging), key=lambda e: (e == _MANIFEST, e))
    if not s.force:
        clash = [e for e in entries if (s.final / e).exists()]
        if clash:
            raise FileExistsError(
                f"{s.final / clash[0]}: appeared while the command ran; use --force to "
                "replace it."
            )
    old = _old_result(s.final, s.names) if s.force else set()
    tx = current_transaction()
    if tx is not None:  # checked before anything is moved
        for e in sorted(old | set(entries)):
            tx.refuse_input(s.final / e)
    trash = s.staging / ".replaced"
    trash.mkdir()
    if _MANIFEST in old:  # the old result is incomplete from here on: say so first
        os.replace(s.final / _MANIFEST, trash / _MANIFEST)
        old.discard(_MANIFEST)
    for e in sorted(old - set(entries)):
        os.replace(s.final / e, trash / e)
    for e in entries:
        if e == ".replaced":
            continue
        target = s.final / e
        if target.is_dir() and not target.is_symlink():
            os.replace(target, trash / e)  # a folder cannot be renamed over a folder
        os.replace(s.staging / e, target)


@contextmanager
def output_transaction() -> Iterator[OutputTransaction]:
    """Stage every result folder that :func:`prepare_output_dir` prepares inside the
    block; move them into place when the block ends normally, discard them otherwise.

    Examples
    --------
    >>> from kinecal.io import output_transaction, prepare_output_dir
    >>> with output_transaction():                             # doctest: +SKIP
    ...     d = prepare_output_dir("results", ["a.csv"])       # a temporary folder
    ...     (d / "a.csv").write_text("x\\n")
    >>> # results/a.csv exists now, complete
    """
    tx = OutputTransaction()
    _stack().append(tx)
    try:
        yield tx
    except BaseException:
        tx.rollback()
        raise
    else:
        tx.commit()
    finally:
        _stack().remove(tx)


def note_input(path: str | Path, what: str = "") -> None:
    """Record ``path`` as an input of the running command (outside a transaction:
    nothing); :func:`refuse_input` then refuses to write over it."""
    for tx in _stack():
        tx.note_input(path, what)


def refuse_input(path: str | Path) -> None:
    """Raise :class:`~kinecal.errors.DataError` if ``path`` is (the same file as) an
    input of the running command: an output never replaces an input, even with
    ``--force``."""
    for tx in _stack():
        tx.refuse_input(path)


def begin_transaction() -> OutputTransaction:
    """Start a transaction (the CLI's form of :func:`output_transaction`); end it with
    :func:`end_transaction` after its commit or rollback."""
    tx = OutputTransaction()
    _stack().append(tx)
    return tx


def end_transaction(tx: OutputTransaction) -> None:
    """Remove ``tx`` from the active ones (rolling back what it did not commit)."""
    tx.rollback()
    if tx in _stack():
        _stack().remove(tx)


def _rmtree(path: Path) -> None:
    """Remove a folder and what it holds, quietly (shutil imported only here: every
    command imports this module, few remove anything; a staging folder moved into
    place is gone already)."""
    if not os.path.lexists(path):
        return
    try:  # without shutil (~2 ms with bz2 and lzma) unless something fails
        if not os.path.islink(path):  # (rmtree refuses a link)
            _remove(path)
            return
    except OSError:
        pass
    import shutil

    shutil.rmtree(path, ignore_errors=True)


def _remove(path: str | Path) -> None:
    """Remove a folder, its files and folders (links themselves, not what they name)."""
    for entry in os.scandir(path):
        if entry.is_dir(follow_symlinks=False):
            _remove(entry.path)
        else:
            os.unlink(entry.path)
    os.rmdir(path)
