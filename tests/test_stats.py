"""Small statistics helpers."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal._stats import median


@pytest.mark.parametrize("shape", [(1,), (7,), (8,), (3, 4), (5, 1, 3)])
def test_median_equals_numpy(shape, rng):
    x = rng.normal(size=shape)
    assert median(x) == float(np.median(x))
    assert median(x.tolist() if x.ndim == 1 else x) == float(np.median(x))


def test_median_of_nothing_is_an_error():
    with pytest.raises(ValueError, match="median of no values"):
        median([])


def test_distinct_rows_counts_as_np_unique_does(rng):
    from kinecal._stats import distinct_rows

    for _ in range(100):
        n, k = int(rng.integers(0, 40)), int(rng.integers(1, 5))
        a = rng.integers(0, 3, size=(n, k)).astype(float)
        assert distinct_rows(a) == np.unique(a, axis=0).shape[0]
    a = rng.normal(size=(500, 8))
    assert distinct_rows(np.vstack([a, a[::7]])) == 500
    with pytest.raises(ValueError, match="2-D"):
        distinct_rows(np.zeros(3))


def test_row_groups_number_equal_rows_by_first_appearance():
    from kinecal._stats import row_groups

    rng = np.random.default_rng(3)
    a = rng.integers(0, 4, size=(200, 3)).astype(float)
    got = row_groups(a)
    _, first, inv = np.unique(a, axis=0, return_index=True, return_inverse=True)
    rank = np.empty(first.size, np.intp)
    rank[np.argsort(first)] = np.arange(first.size)
    assert np.array_equal(got, rank[inv.reshape(-1)])
    assert row_groups(np.zeros((0, 3))).size == 0
