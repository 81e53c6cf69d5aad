"""Debug and info messages of kinecal's modules without importing :mod:`logging` first.

``import logging`` costs ~2 ms (with :mod:`string`), about 1 % of a 2000-pose
``kinecal calibrate`` (issue 36), which shows none of these messages: until something
imports logging (and configures it), its root logger drops every message below WARNING.
A :class:`Logger` hands a message to ``logging.getLogger(name)`` when logging is loaded
(by a user's program, pytest, ...) and drops it otherwise, which is what logging itself
would do. The record names the caller's line and function, as before.
"""

from __future__ import annotations

import sys
from typing import Any

__all__ = ["Logger"]

_DEBUG, _INFO = 10, 20  # logging.DEBUG, logging.INFO


class Logger:
    """``logging.getLogger(name)`` for :meth:`debug` and :meth:`info` messages."""

    def __init__(self, name: str) -> None:
        self.name = name

    def debug(self, msg: str, *args: Any) -> None:
        self._log(_DEBUG, msg, args)

    def info(self, msg: str, *args: Any) -> None:
        self._log(_INFO, msg, args)

    def _log(self, level: int, msg: str, args: tuple[Any, ...]) -> None:
        logging = sys.modules.get("logging")
        if logging is not None:  # else nothing can show it (the default: WARNING)
            # stacklevel 3: the record names the caller of debug()/info()
            logging.getLogger(self.name).log(level, msg, *args, stacklevel=3)
