"""The one rule for a file path kinecal keeps inside a file it writes and reads back (a
model file's ``info.source``, the data it was calibrated on): relative to the folder of
the file that holds it, never to the folder a later command happens to run in.

A model file written in ``cal/`` from data ``sim/train.csv`` holds ``../sim/train.csv``;
read from anywhere, it names the same file (and again when ``cal/`` and ``sim/`` move
together). A text that names no file there (``simulated truth``, a file since moved or
deleted, a model written before this rule, whose path was relative to the folder of its
``calibrate`` run) is a label: no command reads a file from it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

__all__ = ["source_as_read", "source_as_written"]


def source_as_written(source: Any, model_path: str | Path) -> Any:
    """``info.source`` as a model file at ``model_path`` holds it: a data file's
    relative path (as the command was given it: from the current folder) made relative
    to the model file's folder (absolute where there is none, another drive); an
    absolute path, and anything else, as it is. ``model_path`` may be in a command's
    staged result folder: the path is relative to the folder the file will have once
    the result is in place."""
    from kinecal._outputs import user_path

    if not isinstance(source, str) or not source or Path(source).is_absolute():
        return source
    if not Path(source).is_file():
        return source
    final = Path(user_path(str(Path(model_path).absolute())))
    data = os.path.abspath(source)
    try:
        return Path(os.path.relpath(data, final.parent)).as_posix()
    except ValueError:  # another drive (Windows): no relative path
        return data


def source_as_read(source: Any, model_path: str | Path) -> Any:
    """``info.source`` of the model file at ``model_path`` as the commands use it: a
    relative path that names a file in the model file's folder becomes that file's
    absolute path; an absolute path, and a text that names no file there, as written
    (a label: a command reads no file from it). ``model_path`` may be in a staged
    result folder (:func:`source_as_written`)."""
    from kinecal._outputs import user_path

    if not isinstance(source, str) or not source or Path(source).is_absolute():
        return source
    here = Path(user_path(str(Path(model_path).absolute()))).parent / source
    return os.path.normpath(here) if here.is_file() else source
