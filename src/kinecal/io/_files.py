"""Safe output files: atomic writes, no overwrite without ``force``, input hashes."""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from kinecal.errors import DataError

__all__ = [
    "atomic_write_bytes",
    "atomic_write_text",
    "file_sha256",
    "prepare_output_dir",
    "write_json",
]


def file_sha256(path: str | Path) -> str:
    """SHA-256 of a file's bytes (for run manifests)."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
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


def atomic_write_bytes(path: str | Path, data: bytes, *, force: bool = False) -> Path:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename."""
    p = Path(path)
    if p.exists() and not force:
        raise FileExistsError(f"{p} exists; use --force to overwrite it.")
    p.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return p


def write_json(path: str | Path, data: Any, *, force: bool = False) -> Path:
    """Atomically write ``data`` as indented JSON (NaN written as null)."""
    return atomic_write_text(
        path, json.dumps(_clean(data), indent=2) + "\n", force=force
    )


def _clean(x: Any) -> Any:
    import math

    import numpy as np

    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, np.ndarray):
        return _clean(x.tolist())
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return None if not math.isfinite(v) else v
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (np.bool_,)):
        return bool(x)
    return x


def prepare_output_dir(
    path: str | Path, names: list[str], *, force: bool = False
) -> Path:
    """Create an output folder; refuse if any of ``names`` already exists there."""
    d = Path(path)
    if d.exists() and not d.is_dir():
        raise DataError(f"{d} exists and is not a folder.")
    if not force:
        clash = [n for n in names if (d / n).exists()]
        if clash:
            raise FileExistsError(
                f"{d / clash[0]} exists; use --force to overwrite the results in {d}."
            )
    d.mkdir(parents=True, exist_ok=True)
    return d
