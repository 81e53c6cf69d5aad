"""Column-wise CSV writing: numbers formatted by numpy, rows assembled as one byte block.

A fixed-point column (``'%.8f'``) is formatted without a Python call per value: the value
times ``10**decimals`` is rounded to an integer (exactly as printf rounds, ties to even;
the few values within rounding distance of a tie, and non-finite ones, go through
Python's own formatting), its digits are written into a byte matrix, and the rows of all
columns are joined by removing the padding. The output is byte-identical to formatting
each value with ``fmt % value``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from kinecal.io._table import Table

__all__ = ["Column", "csv_text", "format_column", "table_csv"]

_FIXED = re.compile(r"^%\.(\d{1,2})f$")
_CHUNK = 1 << 16  # rows per block: bounds the memory of the byte matrices
_COMMA, _NEWLINE = 44, 10


@dataclass(frozen=True)
class Column:
    """One output column.

    Attributes
    ----------
    values : (N,) numbers (formatted with ``fmt``) or (N,) strings; unused for a copy.
    fmt : printf format of the numbers (``'%.Nf'`` and ``'%d'`` are vectorised).
    copy : name of a column of the input table, copied as written.
    """

    values: np.ndarray | Sequence[str] | None = None
    fmt: str | None = None
    copy: str | None = None

    @classmethod
    def numbers(cls, values: np.ndarray, fmt: str) -> Column:
        return cls(np.asarray(values), fmt)

    @classmethod
    def text(cls, values: Sequence[str]) -> Column:
        return cls(list(values))

    @classmethod
    def labels(cls, labels: Sequence[str], index: np.ndarray) -> Column:
        """Text from a few distinct labels and the index of each row's label."""
        enc = np.array([s.encode("utf-8") for s in labels], dtype=bytes)
        return cls(enc[np.asarray(index, dtype=np.intp)])

    @classmethod
    def copy_of(cls, name: str) -> Column:
        return cls(copy=name)


def _matrix(cells: list[bytes] | np.ndarray) -> np.ndarray:
    """Byte strings as a NUL-padded (N, width) uint8 matrix."""
    a = np.asarray(cells, dtype=bytes) if not isinstance(cells, np.ndarray) else cells
    if a.dtype.itemsize == 0:  # pragma: no cover - numpy gives S1 for empty strings
        return np.zeros((a.shape[0], 1), np.uint8)
    return np.ascontiguousarray(a).view(np.uint8).reshape(a.shape[0], a.dtype.itemsize)


def _digits(k: np.ndarray, count: int) -> list[np.ndarray]:
    """The ``count`` lowest decimal digits of non-negative integers, as ASCII codes,
    lowest first (uint32 arithmetic where the values allow: twice as fast)."""
    r = k.astype(np.uint32) if k.size and int(k.max()) < 2**32 else k.copy()
    ten = r.dtype.type(10)
    out = []
    for _ in range(count):
        q = r // ten
        out.append((r - q * ten).astype(np.uint8) + np.uint8(48))
        r = q
    return out


def _fixed(v: np.ndarray, decimals: int) -> np.ndarray:
    """``'%.{decimals}f' % x`` for every x of ``v`` as a (N, width) uint8 matrix."""
    v = np.asarray(v, dtype=np.float64)
    n = v.shape[0]
    with np.errstate(invalid="ignore", over="ignore"):
        x = np.abs(v) * 10.0**decimals  # exact power of ten (decimals <= 22)
        k = np.rint(x)  # ties to even, as printf on an exact tie
        # Within rounding distance of a tie the product may round the other way than
        # the exact value would; those (and inf, nan, huge values) go through Python.
        python = (
            ~np.isfinite(x)
            | (x >= 2.0**52)
            | (np.abs(x - np.floor(x) - 0.5) <= 2.0 * np.spacing(x))
        )
    fmt = f"%.{decimals}f"
    slow = np.flatnonzero(python)
    texts = [(fmt % float(v[i])).encode() for i in slow]
    k[python] = 0.0
    ku = k.astype(np.uint64)
    frac_w = decimals + 1 if decimals else 0
    top = int(ku.max()) // 10**decimals if n else 0
    int_w = len(str(top))
    w = max([1 + int_w + frac_w, *(len(t) for t in texts)])
    M = np.zeros((n, w), np.uint8)
    ip, fp = np.divmod(ku, np.uint64(10**decimals)) if decimals else (ku, ku)
    for j, d in enumerate(_digits(fp, decimals)):  # fraction digits, right to left
        M[:, w - 1 - j] = d
    if decimals:
        M[:, w - 1 - decimals] = 46  # '.'
    lead = w - frac_w - 1  # the units digit
    first = np.full(n, lead, np.intp)  # position of the leading digit
    for j, d in enumerate(_digits(ip, int_w)):  # integer digits, at least one
        if j == 0:
            M[:, lead] = d
            continue
        live = np.flatnonzero(ip >= 10**j)
        M[live, lead - j] = d[live]
        first[live] = lead - j
    neg = np.flatnonzero(np.signbit(v) & ~python)
    M[neg, first[neg] - 1] = 45  # '-'
    for i, t in zip(slow, texts):
        M[i] = 0
        M[i, w - len(t) :] = np.frombuffer(t, np.uint8)
    return M


def format_column(col: Column, rows: slice) -> np.ndarray:
    """The cells of ``rows`` of a column (values or text) as a (N, width) uint8 matrix."""
    if col.values is None:
        raise ValueError("a copied column needs its table (table_csv).")
    vals = col.values[rows]
    if col.fmt is None:  # text
        if isinstance(vals, np.ndarray) and vals.dtype.kind == "S":
            return _matrix(vals)
        return _matrix([str(s).encode("utf-8") for s in vals])
    m = _FIXED.match(col.fmt)
    if m:
        return _fixed(np.asarray(vals), int(m.group(1)))
    if col.fmt == "%d":
        return _fixed(np.asarray(vals, dtype=np.float64), 0)
    return _matrix([(col.fmt % x).encode() for x in np.asarray(vals).tolist()])


def _join(blocks: list[np.ndarray]) -> bytes:
    """Rows from the cell matrices of each column: cells separated by commas, NUL padding
    dropped, one line per row."""
    n = blocks[0].shape[0]
    width = sum(b.shape[1] for b in blocks) + len(blocks)
    M = np.zeros((n, width), np.uint8)
    off = 0
    for b in blocks:
        M[:, off : off + b.shape[1]] = b
        off += b.shape[1]
        M[:, off] = _COMMA
        off += 1
    M[:, -1] = _NEWLINE
    return M[M != 0].tobytes()


def csv_text(columns: Sequence[tuple[str, Column]]) -> str:
    """A CSV (header and one line per row) of columns of equal length."""
    if not columns:
        raise ValueError("csv_text: no columns.")
    n = len(columns[0][1].values)  # type: ignore[arg-type]
    out = [",".join(name for name, _ in columns) + "\n"]
    for a in range(0, n, _CHUNK):  # text per block: one copy of the output at the end
        rows = slice(a, min(a + _CHUNK, n))
        out.append(_join([format_column(c, rows) for _, c in columns]).decode("utf-8"))
    return "".join(out)


def _raw_cells(t: Table, rows: slice) -> tuple[bytes, np.ndarray, np.ndarray]:
    """The bytes of some data lines and the start/end of every cell, shape (N, C)."""
    buf = ("\n".join(t.data[rows]) + "\n").encode("utf-8")
    b = np.frombuffer(buf, np.uint8)
    ends = np.flatnonzero((b == _COMMA) | (b == _NEWLINE)).reshape(-1, len(t.header))
    starts = np.empty_like(ends)
    starts[:, 1:] = ends[:, :-1] + 1
    starts[0, 0] = 0
    starts[1:, 0] = ends[:-1, -1] + 1
    return buf, starts, ends


def _copied(b: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    length = ends - starts
    w = max(int(length.max()), 1)
    idx = starts[:, None] + np.arange(w)
    out = b[np.minimum(idx, b.size - 1)]
    out[np.arange(w) >= length[:, None]] = 0
    return out


def table_csv(table: Table, columns: Sequence[tuple[str, Column]]) -> str:
    """The rows of ``table`` as a CSV of ``columns``: new values, or input cells copied
    as written (:meth:`Column.copy_of`)."""
    n = len(table)
    head = ",".join(name for name, _ in columns) + "\n"
    if not table.data or "\0" in head:  # a file with quoted cells: row by row
        return head + _table_csv_rows(table, columns)
    out = [head]
    for a in range(0, n, _CHUNK):
        rows = slice(a, min(a + _CHUNK, n))
        buf, starts, ends = _raw_cells(table, rows)
        b = np.frombuffer(buf, np.uint8)
        if (b == 0).any():  # a NUL byte in a cell would be lost: row by row
            return head + _table_csv_rows(table, columns)
        blocks = []
        for _, c in columns:
            if c.copy is not None:
                k = table.header.index(c.copy)
                blocks.append(_copied(b, starts[:, k], ends[:, k]))
            else:
                blocks.append(format_column(c, rows))
        out.append(_join(blocks).decode("utf-8"))
    return "".join(out)


def _table_csv_rows(table: Table, columns: Sequence[tuple[str, Column]]) -> str:
    """:func:`table_csv` row by row (files with quoted cells)."""
    n = len(table)
    cells: list[list[str]] = []
    for _, c in columns:
        if c.copy is not None:
            cells.append(table.column(c.copy))
        else:
            m = format_column(c, slice(0, n))
            cells.append([bytes(r).rstrip(b"\0").lstrip(b"\0").decode() for r in m])
    return "".join(",".join(r) + "\n" for r in zip(*cells))
