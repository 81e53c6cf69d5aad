"""Small statistics helpers shared by the identification and the reports."""

from __future__ import annotations

import numpy as np

from kinecal.typing import ArrayLike

__all__ = ["median"]


def median(values: ArrayLike) -> float:
    """The median of all values (the mean of the two middle ones for an even count).

    Equal to ``float(np.median(values))``, without the import of ``numpy.ma`` that
    np.median and np.quantile make on their first call (10 ms of the command's start).
    """
    v = np.sort(np.ravel(np.asarray(values, dtype=np.float64)))
    if v.size == 0:
        raise ValueError("median of no values")
    return float(0.5 * (v[(v.size - 1) // 2] + v[v.size // 2]))
