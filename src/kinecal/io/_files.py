"""Safe output files: atomic writes, no overwrite without ``force``, input hashes.

Every file is written to a temporary file beside its target, flushed to disk and renamed
over the target, so a reader sees the old file or the new one, never half of one. Files
get the mode a new file normally gets (``0666`` less the user's umask: readable by the
group and others under the usual umask 022), not the ``0600`` of a temporary file.
Folders of several result files are staged as a whole (:mod:`kinecal._outputs`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from kinecal._outputs import new_file_mode, refuse_input
from kinecal.errors import DataError
from kinecal.io._output_paths import output_file

__all__ = [
    "atomic_write_bytes",
    "atomic_write_files",
    "atomic_write_text",
    "file_sha256",
    "json_text",
    "prepare_output_dir",
    "write_json",
]


# Up to this many bytes are hashed by CPython's own SHA-256 (module _sha256; _sha2 from
# 3.12): hashlib's is OpenSSL's, whose library takes 2.5-3 ms to load, as long as the
# builtin takes for ~1 MB (5x slower a byte). The digests are the same.
BUILTIN_SHA256_MAX = 1 << 20


def sha256(data: bytes = b"", size: int | None = None) -> Any:
    """A SHA-256 hash object (``hashlib.sha256(data)``) for ``size`` bytes in all
    (default: ``data``'s): CPython's own for a small input while OpenSSL is not loaded
    (2.5-3 ms of a command, issue 36), OpenSSL's otherwise."""
    size = len(data) if size is None else size
    if size <= BUILTIN_SHA256_MAX and "_hashlib" not in sys.modules:
        try:
            from _sha256 import sha256 as builtin
        except ImportError:  # pragma: no cover - Python 3.12+
            try:
                from _sha2 import sha256 as builtin
            except ImportError:
                builtin = None
        if builtin is not None:
            return builtin(data)
    import hashlib  # not at start-up: commands without a manifest do not need it

    return hashlib.sha256(data)


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes (for run manifests)."""
    with open(path, "rb") as f:
        h = sha256(size=os.fstat(f.fileno()).st_size)
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def atomic_write_text(path: str | Path, text: str, *, force: bool = False) -> Path:
    """Write ``text`` to ``path`` through a temporary file and an atomic rename.

    Raises
    ------
    FileExistsError
        ``path`` exists and ``force`` is False.
    """
    return atomic_write_bytes(path, text.encode("utf-8"), force=force)


def atomic_write_bytes(
    path: str | Path,
    data: bytes | Iterable[bytes],
    *,
    force: bool = False,
    sync: bool = True,
) -> Path:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename.

    ``data`` may come in pieces (an iterable of bytes, written in turn): a large file
    need not be held whole.

    The file gets the mode of a new file (:func:`new_file_mode`). A failure (full disk,
    no permission) leaves ``path`` as it was and removes the temporary file.
    ``sync=False`` skips flushing the file to disk before the rename (10-30 ms a file):
    for many files a crash would simply have to make again; a reader still never sees
    a partial file.

    Raises
    ------
    FileExistsError
        ``path`` exists and ``force`` is False.
    IsADirectoryError
        ``path`` is a folder.
    OSError
        The file cannot be written (permissions, read-only or full file system).
    """
    name, p = Path(path), output_file(path)
    if p.is_dir():
        raise IsADirectoryError(
            f"{name}: is a folder; expected the name of a file to write."
        )
    refuse_input(p)
    if p.exists() and not force:
        raise FileExistsError(f"{name}: exists; use --force to overwrite it.")
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _temp_file(p)
    try:
        with os.fdopen(fd, "wb") as f:
            os.fchmod(f.fileno(), new_file_mode())
            for piece in (data,) if isinstance(data, bytes) else data:
                f.write(piece)
            f.flush()
            if sync:
                os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.errno is not None and not exc.filename:
            # A failed write or fsync names no file: name the one being written.
            raise type(exc)(exc.errno, exc.strerror, str(p)) from exc
        raise
    return name  # (a link: the file it points to is written)


def _temp_file(p: Path) -> tuple[int, str]:
    """A new empty file ``.NAME.XXXXXXXX.tmp`` beside ``p`` (mode 0600), open: the
    rule of ``tempfile.mkstemp``, whose module costs every command 3 ms at start-up
    (it imports shutil, bz2, lzma and random)."""
    flags = os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0)
    flags |= getattr(os, "O_BINARY", 0)
    for _ in range(100):  # a name taken: another (as mkstemp does)
        tmp = os.path.join(p.parent, f".{p.name}.{os.urandom(4).hex()}.tmp")
        try:
            return os.open(tmp, flags, 0o600), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"{p.parent}: no free temporary file name for {p.name}")


def atomic_write_files(
    files: Mapping[str, bytes | str] | Mapping[Path, bytes | str],
    *,
    force: bool = False,
) -> list[Path]:
    """Write several files as one: each to a temporary file beside it first, then all
    renamed into place (Ctrl-C held meanwhile). A failure before the renames leaves
    every target as it was (a command's output and its report: both or neither).

    Raises
    ------
    FileExistsError
        A target exists and ``force`` is False (checked before anything is written).
    """
    from kinecal._outputs import signals_held

    paths = [output_file(p) for p in files]
    check_distinct_outputs(paths)
    for p in paths:
        if p.is_dir():
            raise IsADirectoryError(
                f"{p}: is a folder; expected the name of a file to write."
            )
        refuse_input(p)
        if p.exists() and not force:
            raise FileExistsError(f"{p}: exists; use --force to overwrite it.")
    temps: list[str] = []
    try:
        for p, data in zip(paths, files.values()):
            raw = data.encode("utf-8") if isinstance(data, str) else data
            p.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = _temp_file(p)
            temps.append(tmp)
            try:
                with os.fdopen(fd, "wb") as f:
                    os.fchmod(f.fileno(), new_file_mode())
                    f.write(raw)
                    f.flush()
                    os.fsync(f.fileno())
            except OSError as exc:
                if exc.errno is not None and not exc.filename:
                    raise type(exc)(exc.errno, exc.strerror, str(p)) from exc
                raise
        # Ctrl-C during the renames is taken, not raised: every file is then in place
        # and the command ends normally (a moment later it would have anyway).
        with signals_held([]):
            for tmp, p in zip(temps, paths):
                os.replace(tmp, p)
    finally:
        for tmp in temps:
            if os.path.exists(tmp):
                os.unlink(tmp)
    return [Path(p) for p in files]  # the names given


def check_distinct_outputs(paths: Iterable[str | Path | None]) -> None:
    """Two outputs of one command that are one file (any spelling, a symbolic or hard
    link): the second would replace the first. Refused before anything is written."""
    from kinecal.errors import ConfigError

    seen: list[Path] = []
    for p in (Path(x) for x in paths if x):
        for q in seen:
            same = os.path.realpath(p) == os.path.realpath(q)
            if not same and p.exists() and q.exists():
                same = os.path.samefile(p, q)
            if same:
                both = f"{p}" if str(p) == str(q) else f"{q} and {p} (the same file)"
                raise ConfigError(
                    f"{both}: two outputs of this command would be written to it, the "
                    "second replacing the first; expected a file of its own for each "
                    "(--out, --report, --save-candidates, ...)."
                )
        seen.append(p)


def json_text(data: Any) -> str:
    """``data`` as indented JSON text (NaN and inf written as null)."""
    from kinecal.io._json import dumps

    return dumps(data) + "\n"


def write_json(path: str | Path, data: Any, *, force: bool = False) -> Path:
    """Atomically write ``data`` as indented JSON (NaN written as null)."""
    return atomic_write_text(path, json_text(data), force=force)


def prepare_output_dir(
    path: str | Path, names: list[str], *, force: bool = False
) -> Path:
    """The folder to write a result into; refuse if any of ``names`` exists there.

    ``names`` are the entries the result consists of (file or folder names, or glob
    patterns such as ``model-*.yaml``). Inside an :func:`output_transaction` (every
    ``kinecal`` command runs in one) the returned folder is a temporary one beside or
    inside ``path``, moved into place when the command succeeds (see
    :mod:`kinecal._outputs`); outside one it is ``path`` itself.

    Raises
    ------
    DataError
        ``path`` exists and is not a folder.
    FileExistsError
        One of ``names`` exists in ``path`` and ``force`` is False.
    """
    from kinecal._outputs import _old_result, clashes, current_transaction

    d = Path(path)
    refuse_input(d)
    if d.exists() and not d.is_dir():
        raise DataError(
            f"{d}: exists and is not a folder; expected a folder for the results "
            "(or a new name)."
        )
    if d.is_dir():  # the entries this result replaces: none may be an input
        for e in sorted(_old_result(d, names) if force else clashes(d, names)):
            refuse_input(d / e)
    if not force:
        clash = clashes(d, names)
        if clash:
            raise FileExistsError(
                f"{d / clash[0]}: exists; use --force to replace the results in {d}."
            )
    tx = current_transaction()
    if tx is None:
        d.mkdir(parents=True, exist_ok=True)
        return d
    return tx.stage(d, names, force=force)
