"""The ``kinecal`` program keeps the compiled methods of its dataclasses between runs.

On Python 3.11 and 3.12, :func:`dataclasses.dataclass` writes each method it adds (the
``__init__``, and the ``__setattr__`` and ``__delattr__`` of a frozen class) as source
text and compiles it with :func:`exec`: ~0.1 ms a method, 176 of them (63 classes) in a
2000-pose ``kinecal calibrate``, 17-19 ms of its CPU (8 %, issue 36). Python keeps a
module's compiled code in ``__pycache__``; this keeps those texts' code the same way, in
``__pycache__/dataclass-methods.<cache tag>.bin`` beside kinecal's own bytecode: a text
compiled once is not compiled again (the file holds each code's marshal bytes, made code
when a run first uses it: ~0.4 ms to read the ~400 of all commands). :mod:`dataclasses`
looks its ``exec`` up by name, so :func:`install` puts :func:`exec_cached` there (the
builtin's behaviour, with the compile of a text remembered); the functions it makes are
the ones the builtin makes (the same code: ``compile`` of the same text, with no
inherited ``__future__`` flags, as the builtin called from :mod:`dataclasses` does).

For the program only (:func:`kinecal._entry.run`): a Python program that imports kinecal
keeps its :mod:`dataclasses` as it is. The file is written as bytecode is (not under
``PYTHONDONTWRITEBYTECODE``, and only when something was compiled); where the folder
cannot be written, or the file is unreadable or of another Python, it is just not used.
"""

from __future__ import annotations

import builtins
import marshal
import os
import sys
from pathlib import Path
from types import CodeType
from typing import Any

__all__ = ["exec_cached", "install", "save"]

# text -> its code, or the code's marshal bytes as read from the file (made into code
# when first used: a command uses a part of the ~400 texts the file holds)
_codes: dict[str, CodeType | bytes] = {}
_used: set[str] = set()  # the texts this run compiled or found
_added = 0
# What the code depends on besides its text: the interpreter (marshal format and
# bytecode) and the optimisation level (-O: asserts).
_KEY = (sys.hexversion, sys.implementation.cache_tag, sys.flags.optimize)
# At most this many texts are kept (kinecal's dataclasses need ~200); beyond, those of
# the last run (texts of classes since edited are not kept forever).
MAX_CODES = 4000


def cache_file() -> Path | None:
    """The file, or None where Python keeps no bytecode cache tag."""
    tag = sys.implementation.cache_tag
    if tag is None:  # pragma: no cover - every CPython has one
        return None
    return Path(__file__).parent / "__pycache__" / f"dataclass-methods.{tag}.bin"


def exec_cached(
    source: Any, globals: dict[str, Any] | None = None, locals: Any = None
) -> None:
    """:func:`exec`, with the code of a source text compiled once."""
    global _added
    if globals is None:  # the caller's namespace, as the builtin takes it
        frame = sys._getframe(1)
        globals = frame.f_globals
        locals = frame.f_locals if locals is None else locals
    if type(source) is str:
        code = _codes.get(source)
        if type(code) is bytes:
            try:
                code = marshal.loads(code)
            except (ValueError, EOFError, TypeError):
                code = None
            code = code if type(code) is CodeType else None
        if code is None:
            code = compile(source, "<string>", "exec", dont_inherit=True)
            _added += 1
        _codes[source] = code
        _used.add(source)
        source = code
    if locals is None:
        builtins.exec(source, globals)
    else:
        builtins.exec(source, globals, locals)


def install() -> bool:
    """Load the file's code and let :mod:`dataclasses` compile through
    :func:`exec_cached`; False (nothing changed) where it would not take effect."""
    import dataclasses

    path = cache_file()
    if path is None:  # pragma: no cover
        return False
    try:
        key, codes = marshal.loads(path.read_bytes())
        if key == _KEY and isinstance(codes, dict):
            _codes.update(
                (k, v) for k, v in codes.items() if type(k) is str and type(v) is bytes
            )
    except (OSError, ValueError, EOFError, TypeError):
        pass  # none yet, or not ours: compiled anew (and written again)
    dataclasses.exec = exec_cached  # type: ignore[attr-defined]
    return True


def save() -> None:
    """Write the file when texts were compiled in this run (as bytecode is written:
    not under ``PYTHONDONTWRITEBYTECODE``); a folder that cannot be written is left
    alone."""
    global _added
    path = cache_file()
    if not _added or path is None or sys.dont_write_bytecode:
        return
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    keep = _codes.keys() if len(_codes) <= MAX_CODES else _used
    codes = {
        k: v if type(v) is bytes else marshal.dumps(v)
        for k, v in _codes.items()
        if k in keep
    }
    try:
        path.parent.mkdir(exist_ok=True)
        tmp.write_bytes(marshal.dumps((_KEY, codes)))
        os.replace(tmp, path)  # a reader sees the old file or the new one
        _added = 0
    except OSError:
        try:
            tmp.unlink()
        except OSError:
            pass
