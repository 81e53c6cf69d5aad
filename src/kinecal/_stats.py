"""Small statistics helpers shared by the identification and the reports.

np.median, np.quantile, np.unique and np.isin import ``numpy.ma`` on their first call
(5-10 ms of a command's start); these do the same without it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kinecal.typing import ArrayLike, Float, Int

__all__ = [
    "distinct_rows",
    "first_rows",
    "median",
    "present",
    "quantiles",
    "row_groups",
]


def median(values: ArrayLike) -> float:
    """The median of all values (the mean of the two middle ones for an even count).

    Equal to ``float(np.median(values))``, without the import of ``numpy.ma`` that
    np.median and np.quantile make on their first call (10 ms of the command's start).
    """
    v = np.sort(np.ravel(np.asarray(values, dtype=np.float64)))
    if v.size == 0:
        raise ValueError("median of no values")
    return float(0.5 * (v[(v.size - 1) // 2] + v[v.size // 2]))


def distinct_rows(rows: ArrayLike) -> int:
    """The number of distinct rows of a 2-D array (equal rows counted once).

    Equal to ``np.unique(rows, axis=0).shape[0]``, which imports ``numpy.ma`` on its
    first call (5 ms of a command's start) and sorts the rows as raw bytes; here one
    lexicographic sort and a comparison of neighbours. -0.0 and 0.0 count as equal.
    """
    a = np.asarray(rows)
    if a.ndim != 2:
        raise ValueError(f"distinct_rows expects a 2-D array; got {a.ndim}-D")
    if a.shape[0] <= 1:
        return int(a.shape[0])
    s = a[np.lexsort(a.T[::-1])]
    return 1 + int(np.count_nonzero(np.any(s[1:] != s[:-1], axis=1)))


def first_rows(labels: ArrayLike) -> Int:
    """The first row of every label 0..max of an array of non-negative integer labels
    (the array's length for a label that does not occur)."""
    a = np.ravel(np.asarray(labels))
    first = np.full(int(a.max()) + 1 if a.size else 0, a.size, np.intp)
    np.minimum.at(first, a, np.arange(a.size))
    return first


def row_groups(rows: ArrayLike) -> Int:
    """A label per row of a 2-D array, equal rows sharing one, numbered 0, 1, ... by
    first appearance (``np.unique(rows, axis=0, return_inverse=True)`` renumbered,
    without numpy.ma)."""
    a = np.asarray(rows)
    n = a.shape[0]
    if n == 0:
        return np.zeros(0, np.intp)
    order = np.lexsort(a.T[::-1])
    s = a[order]
    new = np.ones(n, bool)
    new[1:] = np.any(s[1:] != s[:-1], axis=1)
    inverse = np.empty(n, np.intp)
    inverse[order] = np.cumsum(new) - 1
    first = first_rows(inverse)
    rank = np.empty(first.size, np.intp)
    rank[np.argsort(first)] = np.arange(first.size)
    return rank[inverse]


def quantiles(v: ArrayLike, q: Sequence[float]) -> Float:
    """Linear-interpolation quantiles of all values (``np.quantile``'s default method);
    NaN for no values."""
    s = np.sort(np.ravel(np.asarray(v, float)))
    if s.size == 0:
        return np.full(len(q), np.nan)
    pos = np.asarray(q, float) * (s.size - 1)
    i = np.floor(pos).astype(int)
    j = np.minimum(i + 1, s.size - 1)
    return s[i] + (pos - i) * (s[j] - s[i])


def present(index: ArrayLike) -> Int:
    """The distinct values of an array of non-negative integers (set, marker or target
    indices), ascending: ``np.unique`` of such an array."""
    a = np.ravel(np.asarray(index))
    if a.size == 0:
        return np.zeros(0, np.intp)
    return np.flatnonzero(np.bincount(a))
