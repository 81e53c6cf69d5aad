"""Numbers to text in bulk: the text ``'%d' % i`` and ``'%.6f' % x`` give, vectorised.

A result folder's text is mostly numbers: residuals.csv (18 columns per pose) and the
report's figures (two pixel coordinates per dot). Python's ``%`` formats them one object
at a time (~0.1-0.2 us each: 6 ms for a 2000-pose residuals.csv and 6 ms for the
report's SVG paths, issue 36). Here every number becomes one or two 8-byte words of
ASCII by integer arithmetic on arrays: its digits looked up four at a time in a table,
right-aligned, with zero bytes in front; the rows are laid out side by side and the zero
bytes dropped at once. The text is ``%``'s, byte for byte (tests/test_numtext.py): the
six decimals of ``%.6f`` are the integer nearest to ``x * 1e6``, taken from the array
where that product lies clearly off a half, else from ``%`` itself. Values these words
do not hold (|x| of a million or more, not finite): ``%``.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from kinecal.typing import ArrayLike

__all__ = ["csv_lines", "int_fields", "int_row_groups", "int_rows", "join_rows"]

Fields = np.ndarray  # (n, W) uint8: one right-aligned field per row, 0 = no byte

# Integers a word holds: a separator byte, a sign and six digits.
_LIMIT = 10**6
_tables: dict[str, np.ndarray] | None = None


def _word(*at: tuple[int, int]) -> np.uint64:
    """A word with the given (byte index, value) pairs, in memory order."""
    b = bytearray(8)
    for i, v in at:
        b[i] = v
    return np.frombuffer(bytes(b), np.uint64)[0]


def _digit_tables() -> dict[str, np.ndarray]:
    """Words (uint64, bytes in memory order) that are ORed into a number's text:

    lo : (4 * 10^4,) the last four digits of an integer under 10^6, right-aligned in
        the word: [small, small negative, below a high part (zero-padded), the same];
    hi : (2 * 100,) its high part (the integer // 10^4): digits ending at byte 3,
        [positive, negative]; nothing for 0;
    dec : (100,) '.' and two decimals (bytes 0-2); dec4 (10^4,) four more (bytes 3-6).
    """
    global _tables
    if _tables is None:
        # (slices and broadcasting only: arithmetic on 10^4 integers took 1.3 ms)
        d = np.arange(ord("0"), ord("9") + 1, dtype=np.uint8)
        digits = np.empty((10, 10, 10, 10, 4), np.uint8)  # 0000 ... 9999
        for i, shape in enumerate(((10, 1, 1, 1), (10, 1, 1), (10, 1), (10,))):
            digits[..., i] = d.reshape(shape)
        pad = digits.reshape(10_000, 4)
        lead = pad.copy()  # no leading zeros: 1, 2 and 3 digits
        lead[:1000, 0], lead[:100, 1], lead[:10, 2] = 0, 0, 0
        starts = (0, 10, 100, 1000, 10_000)  # of the numbers of 1, 2, 3, 4 digits
        lo = np.zeros((4, 10_000, 8), np.uint8)
        lo4 = lo.view(np.uint32)  # (copies of four bytes at once: 8x faster)
        lo4[:2, :, 1] = lead.view(np.uint32)[:, 0]
        lo4[2:, :, 1] = pad.view(np.uint32)[:, 0]
        hi = np.zeros((2, 100, 8), np.uint8)
        hi[:, 1:, :4] = lead[1:100]
        for n, (a, b) in enumerate(itertools.pairwise(starts), start=1):
            lo[1, a:b, 7 - n] = ord("-")  # the sign before the digits
            if n <= 2:
                hi[1, max(a, 1) : min(b, 100), 3 - n] = ord("-")
        dec = np.zeros((100, 8), np.uint8)
        dec[:, 0], dec[:, 1:3] = ord("."), pad[:100, 2:]
        dec4 = np.zeros((10_000, 8), np.uint8)
        np.ndarray((10_000,), np.uint32, dec4, 3, (8,))[:] = pad.view(np.uint32)[:, 0]
        _tables = {
            name: np.ascontiguousarray(t).view(np.uint64).ravel()
            for name, t in (("lo", lo), ("hi", hi), ("dec", dec), ("dec4", dec4))
        }
    return _tables


def _int_words(v: np.ndarray, neg: np.ndarray) -> np.ndarray:
    """One word per integer ``v`` (floats, whole, 0 <= v < 10^6): byte 0 empty (for a
    separator), then zero bytes, '-' where ``neg``, the digits."""
    t = _digit_tables()
    hi = np.floor(v / 1e4)  # exact: a correctly rounded quotient of whole numbers
    lo = (v - hi * 1e4).astype(np.intp)
    big, sign = hi > 0, neg.astype(np.intp)
    hi_i = hi.astype(np.intp)
    return t["hi"][hi_i + 100 * sign] | t["lo"][lo + 10_000 * (2 * big + sign)]


def int_fields(values: ArrayLike) -> Fields:
    """``'%d' % v`` of each integer (n,) as fields (n, W)."""
    v = np.asarray(values).ravel()
    if v.dtype.kind not in "iu":
        raise TypeError(f"int_fields: integers expected; got {v.dtype}")
    if not v.size or (v.max() < _LIMIT and v.min() > -_LIMIT):
        w = _int_words(np.abs(v).astype(np.float64), v < 0)
        return w.view(np.uint8).reshape(v.size, 8)
    texts = [f"{x}" for x in v.tolist()]
    width = max(map(len, texts), default=1)
    data = "".join(t.rjust(width, "\0") for t in texts).encode("ascii")
    return np.frombuffer(data, np.uint8).reshape(v.size, width)


def _fixed6_words(x: np.ndarray) -> np.ndarray | None:
    """(n, k, 2) uint64: ``'%.6f'`` of the floats ``x`` (n, k), byte 0 and byte 15
    of each empty (for separators); None when a value is not finite or is 10^6 or
    more in magnitude."""
    y = np.abs(x) * 1e6
    k = np.rint(y)
    with np.errstate(invalid="ignore"):
        if not (k < _LIMIT * 1e6 - 0.5).all():  # also: not finite
            return None
        # the nearest integer is %'s rounding of the exact product unless that lies
        # within the product's own rounding error of a half (see report._poses)
        near_half = np.abs(np.abs(y - k) - 0.5) <= 4 * np.spacing(y)
    if near_half.any():
        at = np.nonzero(near_half)
        texts = [f"{v:.6f}" for v in x[at].tolist()]
        k[at] = [int(t.lstrip("-").replace(".", "")) for t in texts]
        if k.max() >= _LIMIT * 1e6:
            return None
    t = _digit_tables()
    whole = np.floor(k / 1e6)  # exact (see _int_words)
    frac = k - whole * 1e6
    hi = np.floor(frac / 1e4)
    lo = (frac - hi * 1e4).astype(np.intp)
    out = np.empty((*x.shape, 2), np.uint64)
    out[..., 0] = _int_words(whole, np.signbit(x))
    out[..., 1] = t["dec"][hi.astype(np.intp)] | t["dec4"][lo]
    return out


def csv_lines(ints: ArrayLike, floats: ArrayLike) -> str | None:
    """The lines ``'%d' + ',%.6f' * k + '\\n'`` of every row of ``ints`` (n,) and
    ``floats`` (n, k), one string; None where these words cannot write them (then
    ``%`` must)."""
    i, x = np.asarray(ints).ravel(), np.asarray(floats, np.float64)
    if x.ndim != 2 or i.size != x.shape[0] or not x.shape[1]:
        return None
    if i.size and not (i.max() < _LIMIT and i.min() > -_LIMIT):
        return None
    words = _fixed6_words(x)
    if words is None:
        return None
    words[:, :, 0] |= _word((0, ord(",")))  # the separator before each value
    words[:, -1, 1] |= _word((7, ord("\n")))
    line = np.empty((i.size, 1 + 2 * x.shape[1]), np.uint64)
    line[:, 0] = _int_words(np.abs(i).astype(np.float64), i < 0)
    line[:, 1:] = words.reshape(i.size, 2 * x.shape[1])
    flat = line.view(np.uint8).ravel()
    return flat[flat != 0].tobytes().decode("ascii")


# Fewer numbers than this are formatted by % (the arrays' fixed cost is ~30 us).
SMALL = 1000


def int_rows(fmt: str, columns: Sequence[np.ndarray]) -> str:
    """``fmt`` (ASCII, one ``%d`` per column and no other ``%``) filled with each row
    of the integer ``columns`` (n,) in turn, the rows concatenated."""
    return int_row_groups(fmt, columns, ())[0]


def int_row_groups(
    fmt: str, columns: Sequence[np.ndarray], bounds: Sequence[int]
) -> list[str]:
    """:func:`int_rows` of the rows ``[0, b0)``, ``[b0, b1)``, ... ``[bk, n)`` of the
    ``columns`` (``bounds``: increasing row numbers), each group's text apart."""
    between = fmt.split("%d")
    if len(between) != len(columns) + 1 or "%" in "".join(between):
        raise ValueError(f"int_rows: {fmt!r} for {len(columns)} columns")
    a = np.column_stack([np.ravel(c) for c in columns])
    n, k = a.shape
    edges = [0, *bounds, n]
    if a.size < SMALL or a.max() >= _LIMIT or a.min() <= -_LIMIT:
        return [
            (fmt * (hi - lo)) % tuple(a[lo:hi].ravel().tolist())
            for lo, hi in itertools.pairwise(edges)
        ]
    words = _int_words(np.abs(a).astype(np.float64), a < 0)
    if any(len(t) > 1 for t in between[:-1]):
        b = words.view(np.uint8)
        return _texts(
            _layout(between, [b[:, 8 * j : 8 * j + 8] for j in range(k)]), edges
        )
    # each text before a number in its word's first byte, the last one after them
    words |= np.array([_word((0, ord(t))) if t else 0 for t in between[:-1]], np.uint64)
    tail = between[-1].encode("ascii")
    tail += bytes(-len(tail) % 8)
    line = np.empty((n, k + len(tail) // 8), np.uint64)
    line[:, :k] = words
    line[:, k:] = np.frombuffer(tail, np.uint64)
    return _texts(line.view(np.uint8), edges)


def _texts(rows: np.ndarray, edges: Sequence[int] | None = None) -> list[str]:
    """The text of the bytes ``rows`` (n, W) without their zero bytes, cut at the rows
    ``edges`` (0, ..., n; None or two: one text)."""
    keep = rows != 0
    text = rows[keep].tobytes().decode("ascii")
    if edges is None or len(edges) == 2:
        return [text]
    out, at = [], 0
    for lo, hi in itertools.pairwise(edges):
        size = int(np.count_nonzero(rows[lo:hi]))  # the group's bytes of text
        out.append(text[at : at + size])
        at += size
    return out


def _layout(between: Sequence[str], fields: Sequence[Fields]) -> np.ndarray:
    """(n, W) bytes: each row's ``between[0]``, ``fields[0][i]``, ``between[1]``, ...,
    ``between[-1]`` side by side (zero bytes in the fields are no text)."""
    if len(between) != len(fields) + 1:
        raise ValueError("join_rows: one text more than fields expected")
    n = fields[0].shape[0] if fields else 0
    text = [np.frombuffer(s.encode("ascii"), np.uint8) for s in between]
    width = sum(t.size for t in text) + sum(f.shape[1] for f in fields)
    out = np.empty((n, width), np.uint8)
    at = 0
    for t, f in zip(text, [*fields, None]):
        out[:, at : at + t.size] = t
        at += t.size
        if f is not None:
            out[:, at : at + f.shape[1]] = f
            at += f.shape[1]
    return out


def join_rows(between: Sequence[str], fields: Sequence[Fields]) -> str:
    """Every row's text: ``between[0] + fields[0][i] + between[1] + ... +
    between[-1]`` for row i, the rows concatenated (``len(between) == len(fields) + 1``;
    the text between the fields ASCII without NUL)."""
    return _texts(_layout(between, fields))[0]
