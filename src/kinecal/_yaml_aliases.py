"""A YAML document whose aliases expand it beyond reason is refused before it is built.

An anchor (``&a``) and its aliases (``*a``) let a short file stand for a huge document:
ten aliases of a list of ten aliases of ... ("billion laughs") make a 1 kB model.yaml a
billion values. PyYAML shares the aliased objects, so reading it costs nothing, but any
code that walks the values (a message quoting ``info.source``, a JSON dump, a
fingerprint) then spends minutes and gigabytes on them: ``kinecal fk`` printed a 2 GB
warning. The composed node graph is measured first: the values it expands to, each alias
counted in full, against those written. Files kinecal writes have no aliases; a robot
file that names its limits once (``&lim``) and reuses them stays far below the bound.
"""

from __future__ import annotations

from typing import Any

__all__ = ["MAX_EXTRA", "check_expansion"]

MAX_EXTRA = 100_000
"""Values a document may gain through its aliases beyond 10 x those written."""


def check_expansion(node: Any) -> None:
    """Raise ``ValueError`` (with the line) if the node graph under ``node`` expands to
    more than 10 x its distinct nodes + :data:`MAX_EXTRA` values, or holds itself."""
    size: dict[int, int] = {}
    busy: set[int] = set()
    stack: list[tuple[Any, bool]] = [(node, False)]
    while stack:
        n, done = stack.pop()
        key = id(n)
        kids = _children(n)
        if done:
            busy.discard(key)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            continue
        if key in size:
            continue
        if key in busy:
            raise ValueError(
                f"line {n.start_mark.line + 1}: an alias holds the collection it is in "
                "(a recursive document); expected a plain document"
            )
        busy.add(key)
        stack.append((n, True))
        stack.extend((k, False) for k in kids if id(k) not in size)
    total, written = size[id(node)], len(size)
    if total > 10 * written + MAX_EXTRA:
        raise ValueError(
            f"its aliases (*name) expand {written} values written to {total:.3g}; "
            f"expected at most {10 * written + MAX_EXTRA} (a document built to exhaust "
            "memory, 'billion laughs'?)"
        )


def _children(n: Any) -> list[Any]:
    value = getattr(n, "value", None)
    if not isinstance(value, list):
        return []
    if value and isinstance(value[0], tuple):  # a mapping: (key, value) pairs
        return [x for pair in value for x in pair]
    return value
