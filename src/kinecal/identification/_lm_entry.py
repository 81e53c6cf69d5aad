"""The entry checks of :func:`~kinecal.identification.solve_lm` (scipy-style: a
ValueError naming the argument and the shapes, issue 32 point 4)."""

from __future__ import annotations

from typing import Any

import numpy as np

from kinecal.typing import ArrayLike, Float

__all__ = ["check_first_evaluation", "checked_start"]


def checked_start(
    x0: ArrayLike, free: ArrayLike, scales: ArrayLike
) -> tuple[Float, np.ndarray, Float]:
    """``x0``, ``free`` and ``scales`` as arrays, validated (scipy-style: a ValueError
    naming the argument and the shapes)."""
    x = np.array(x0, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"solve_lm: x0 must be a vector (P,); got shape {x.shape}.")
    f = np.asarray(free)
    if f.shape != x.shape:
        raise ValueError(
            f"solve_lm: free must have the shape of x0 {x.shape}; got {f.shape}."
        )
    if f.dtype != np.bool_:
        raise ValueError(f"solve_lm: free must be booleans; got dtype {f.dtype}.")
    sc = np.asarray(scales, dtype=np.float64)
    if sc.shape != x.shape:
        raise ValueError(
            f"solve_lm: scales must have the shape of x0 {x.shape}; got {sc.shape}."
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(
            f"solve_lm: x0 must be finite; entries {np.flatnonzero(~np.isfinite(x))[:5]}"
            " are not."
        )
    bad = ~(np.isfinite(sc) & (sc > 0)) & f
    if np.any(bad):
        raise ValueError(
            "solve_lm: scales of the free parameters must be finite and > 0; entries "
            f"{np.flatnonzero(bad)[:5]} are not."
        )
    return x, f, sc


def check_first_evaluation(r: Any, J: object, size: int) -> None:
    """The residuals and the Jacobian of ``fun`` at ``x0``: finite, of matching
    shapes (a NaN at the start would otherwise end as "stalled")."""
    if J is None:
        raise ValueError("solve_lm: fun(x, True) must return a Jacobian; got None.")
    r = np.asarray(r)
    if r.ndim < 1 or r.size == 0:
        raise ValueError(
            f"solve_lm: fun(x0) must return residual rows (N, c); got shape {r.shape}."
        )
    if not np.all(np.isfinite(r)):
        n_bad = int(np.count_nonzero(~np.isfinite(r)))
        raise ValueError(
            f"solve_lm: the residuals at x0 are not finite ({n_bad} of {r.size} "
            "entries NaN or inf); check the data and the start."
        )
    if isinstance(J, np.ndarray) and (
        J.shape[:-1] != r.shape or J.ndim != r.ndim + 1 or J.shape[-1] < size
    ):
        # (a lifted stage's Jacobian carries extra product columns after the P)
        raise ValueError(
            f"solve_lm: the Jacobian at x0 must have shape {(*r.shape, size)} (residuals "
            f"{r.shape} by {size} parameters of x0); got {J.shape}."
        )
