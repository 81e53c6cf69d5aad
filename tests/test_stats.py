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
