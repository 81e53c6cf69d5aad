"""The run manifest (``manifest.json``) of a command's result folder: the version, the
command line, the resolved settings, the inputs' and the outputs' SHA-256."""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["manifest"]


def manifest(
    inputs: dict[str, str | None],
    config: dict[str, Any],
    files: list[str] | None = None,
    folder: Path | None = None,
) -> dict[str, Any]:
    """Run manifest: version, command line, resolved config, input file hashes and the
    result's files (``files``: what ``--force`` replaces as a whole next time); with
    ``folder``, the SHA-256 of each of those files already written there
    (``outputs``: ``kinecal report`` refuses a folder whose files come from different
    runs)."""
    from kinecal._version import __version__
    from kinecal.io import file_sha256

    hashes = {}
    for key, path in inputs.items():
        if path and Path(path).is_file():
            hashes[key] = {"path": str(path), "sha256": file_sha256(path)}
    return {
        "kinecal_version": __version__,
        "command": " ".join(["kinecal", *sys.argv[1:]]),
        "python": sys.version.split()[0],
        "config": config,
        "inputs": hashes,
        # each once (a caller may list manifest.json already)
        "files": list(
            dict.fromkeys(
                [*(files or []), *([] if files is None else ["manifest.json"])]
            )
        ),
        **(
            {}
            if folder is None
            else {
                "outputs": {
                    f: file_sha256(folder / f)
                    for f in files or []
                    if f != "manifest.json" and (folder / f).is_file()
                }
            }
        ),
        "created_unix": time.time(),
    }
