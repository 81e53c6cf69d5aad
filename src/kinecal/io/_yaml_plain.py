"""The YAML text of a plain document without PyYAML (issue 36).

``import yaml`` costs ~10 ms (its reader compiles a large regular expression), 3-4 % of
a 2000-pose ``kinecal calibrate``, which only writes model.yaml. :func:`dump` writes the
very text of :func:`kinecal._yaml.dump` (PyYAML's safe dumper; ``sort_keys=False,
allow_unicode=True, width=100``) for the documents kinecal writes: mappings (string
keys) and lists in block style, empty ones as ``{}`` and ``[]``; numbers, booleans,
null, the empty string as ``''``; strings that need no quotes. Anything else (a string
YAML would quote or read as another type, a long key, a type outside these) returns
None (so does a string of an exponent number, ``12e5``, which kinecal's reader takes
for a number and its dumper quotes): the caller then lets PyYAML write the document.
Such a document also reads back as itself (``yaml.load(dump(doc)) == doc``).
"""

from __future__ import annotations

import math
import re
from typing import Any

from kinecal._yaml_float import EXPONENT_FLOAT

__all__ = ["dump"]

# Plain (unquoted) strings, at most 100 characters (a key of more than 128 would be
# written as a complex key, a value may wrap past the line width): a letter, '_' or '/'
# first (never an indicator, a number or .inf), then letters, digits and _ . / @ + -;
# digits and lowercase letters with a letter, not 0x.. or 0b.. (a hash: never a number
# or a date); a version a.b.c (never a float).
_PLAIN = re.compile(
    r"[A-Za-z_/][A-Za-z0-9_./@+-]{0,99}"
    r"|\.\.?/[A-Za-z0-9_./@+-]{0,97}"  # a relative path: ./ or ../ first
    r"|(?!0[xb])(?=[0-9a-z]{0,100}$)[0-9]+[a-z][0-9a-z]*"
    r"|(?=.{0,100}$)[0-9]+(?:\.[0-9]+){2,}"
)
# Words YAML 1.1 (PyYAML's resolver) reads as booleans or null: quoted.
_WORDS = frozenset(
    f(w)
    for w in ("yes", "no", "true", "false", "on", "off", "null")
    for f in (str.lower, str.capitalize, str.upper)
)


class _Other(Exception):
    """A value outside what :func:`dump` writes."""


def dump(doc: dict[str, Any]) -> str | None:
    """The YAML text of the mapping ``doc`` as PyYAML writes it, or None."""
    if type(doc) is not dict or not doc:
        return None
    lines: list[str] = []
    try:
        _mapping(doc, 0, "", lines)
    except _Other:
        return None
    return "\n".join(lines) + "\n"


def _scalar(x: Any) -> str | None:
    """The text of a scalar, '[]' / '{}' for an empty collection, None otherwise."""
    t = type(x)
    if t is str:
        if not x:
            return "''"
        if x in _WORDS or not _PLAIN.fullmatch(x) or EXPONENT_FLOAT.match(x):
            raise _Other
        return x
    if t is bool:
        return "true" if x else "false"
    if t is int:
        return str(x)
    if t is float:
        if math.isnan(x):
            return ".nan"
        if math.isinf(x):
            return ".inf" if x > 0 else "-.inf"
        s = repr(x).lower()
        return s.replace("e", ".0e", 1) if "." not in s and "e" in s else s
    if x is None:
        return "null"
    if t is dict or t is list:
        return None if x else ("{}" if t is dict else "[]")
    raise _Other


def _mapping(d: dict[str, Any], indent: int, lead: str, lines: list[str]) -> None:
    """A block mapping at column ``indent``; its first line starts with ``lead``."""
    pad = " " * indent
    for k, v in d.items():
        if type(k) is not str or not k or len(k) > 100:
            raise _Other
        key = f"{lead or pad}{_scalar(k)}:"
        lead = ""
        s = _scalar(v)
        if s is not None:
            lines.append(f"{key} {s}")
        elif type(v) is dict:
            lines.append(key)
            _mapping(v, indent + 2, "", lines)
        else:  # a list in a mapping: its dashes at the key's column
            lines.append(key)
            _sequence(v, indent, "", lines)


def _sequence(items: list[Any], indent: int, lead: str, lines: list[str]) -> None:
    """A block sequence at column ``indent``; its first line starts with ``lead``."""
    pad = " " * indent
    for v in items:
        dash = f"{lead or pad}- "
        lead = ""
        s = _scalar(v)
        if s is not None:
            lines.append(dash + s)
        elif type(v) is dict:
            _mapping(v, indent + 2, dash, lines)
        else:
            _sequence(v, indent + 2, dash, lines)
