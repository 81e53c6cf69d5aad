"""One ``__eq__``, ``__hash__`` and ``__repr__`` for kinecal's dataclasses.

On Python 3.11 :func:`dataclasses.dataclass` writes each method it adds as source text
and compiles it: ~0.07 ms a method, and the ~60 dataclasses a 2000-pose ``kinecal
calibrate`` loads took 30-35 ms to make (12 % of the command, issue 36), a third of it
for ``__eq__``, ``__hash__`` and ``__repr__`` that almost nothing calls. A class declared
``@dataclass(eq=False, repr=False)`` on :class:`Record` (frozen) or
:class:`MutableRecord` gets these three from here instead: the same methods, with the
same results, as ``dataclass`` would have written (its fields in order; ``repr`` of the
fields with ``repr=True``, ``==`` of the same class over the fields with
``compare=True``, ``hash`` over ``compare`` or ``hash=True`` fields; a mutable record
unhashable; ``...`` for a record inside its own repr). A dataclass with ``eq=False`` gets
its repr alone from :class:`ReprRecord`.
"""

from __future__ import annotations

import dataclasses
import reprlib
from typing import Any, ClassVar

__all__ = ["MutableRecord", "Record", "ReprRecord"]


_NAMES: dict[tuple[Any, str], tuple[str, ...]] = {}


def _names(cls: Any, what: str) -> tuple[str, ...]:
    """The fields of ``cls`` that its ``what`` ('repr', 'eq', 'hash') reads, in order."""
    names = _NAMES.get((cls, what))
    if names is None:
        fields = dataclasses.fields(cls)
        if what == "repr":
            names = tuple(f.name for f in fields if f.repr)
        elif what == "eq":
            names = tuple(f.name for f in fields if f.compare)
        else:
            names = tuple(
                f.name for f in fields if (f.compare if f.hash is None else f.hash)
            )
        _NAMES[cls, what] = names
    return names


class ReprRecord:
    """Base of a ``@dataclass(eq=False, repr=False)`` compared as an object (the
    identity's ``==`` and hash): the ``__repr__`` of ``@dataclass(eq=False)``."""

    __slots__ = ()

    @reprlib.recursive_repr()
    def __repr__(self) -> str:
        names = _names(self.__class__, "repr")
        inner = ", ".join(f"{n}={getattr(self, n)!r}" for n in names)
        return f"{self.__class__.__qualname__}({inner})"


class Record(ReprRecord):
    """Base of a frozen ``@dataclass(frozen=True, eq=False, repr=False)``: the
    ``__eq__``, ``__hash__`` and ``__repr__`` of ``@dataclass(frozen=True)``."""

    __slots__ = ()

    def __eq__(self, other: object) -> bool:
        if other.__class__ is self.__class__:
            names = _names(self.__class__, "eq")
            return tuple(getattr(self, n) for n in names) == tuple(
                getattr(other, n) for n in names
            )
        return NotImplemented

    def __hash__(self) -> int:
        return hash(tuple(getattr(self, n) for n in _names(self.__class__, "hash")))


class MutableRecord(Record):
    """Base of a ``@dataclass(eq=False, repr=False)`` (not frozen): the ``__eq__`` and
    ``__repr__`` of ``@dataclass``, and no hash (as ``dataclass`` sets for a mutable
    class with ``__eq__``)."""

    __slots__ = ()
    __hash__: ClassVar[Any] = None
