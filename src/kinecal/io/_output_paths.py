"""The file an output name stands for, before it is written atomically
(:mod:`._files`: a temporary file beside it, renamed over it).

- A symbolic link: the file it points to is written (the link stays). The rename
  replaced the link itself by a plain file, and the file it pointed to kept its old
  content: an ``--out`` link into a shared results folder left that folder stale.
- A device, pipe or socket (``--out /dev/stdout``, a FIFO): refused. The rename
  replaced the device node by a plain file (as root, ``/dev/stdout`` itself).
- A name ending in ``/`` (a folder meant): refused. ``--out new/`` wrote a file
  ``new``.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from kinecal.errors import DataError

__all__ = ["output_file"]


def output_file(path: str | Path) -> Path:
    """The regular file to write for the output name ``path`` (see the module).

    Raises
    ------
    DataError
        ``path`` ends in a path separator, or is a device, pipe or socket.
    """
    raw = os.fspath(path)
    p = Path(raw)
    if raw.endswith(("/", os.sep)) and not p.is_dir():
        raise DataError(
            f"{raw}: ends in '{raw[-1]}' (a folder); expected the name of a file to "
            "write."
        )
    try:
        mode = os.stat(p).st_mode  # through links: what the name writes into
    except OSError:
        mode = None
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise DataError(
            f"{raw}: is not a regular file (a device, pipe or socket); expected the "
            "name of a file to write (the output is written to a new file and renamed "
            "into place)."
        )
    if p.is_symlink():
        p = Path(os.path.realpath(p))
    return p
