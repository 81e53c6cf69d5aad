"""Whether a candidate's Fourier transmission terms (Eq. (16)) are set by the data or by
where the poses happened to be: their coefficients across the region folds' fits.

A Fourier series of a joint angle fitted on one pose distribution can predict held-out
regions well and still not carry over to a new session (issue 31: the FR3 halves, a
real UR10). What its region folds do show is whether its coefficients are reproducible:
fitted without each region in turn, a term the arm really has keeps its value, a term
that follows the pose distribution swings with it. The test is a delete-one-region
jackknife (docs/theory.md, "Accuracy on a new session", Eq. (T-12)).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import replace

import numpy as np

from kinecal.models import ModelSpec, ParameterLayout
from kinecal.typing import Float

__all__ = [
    "FoldCoefficients",
    "fold_fourier",
    "fourier_terms",
    "jackknife_z2",
    "null_z2",
    "same_physics",
]

FoldCoefficients = dict[str, tuple[float, ...]]  # parameter name -> value per fold


def fourier_terms(spec: ModelSpec) -> int:
    """How many Fourier orders the layout has over all joints."""
    return len(spec.ntm_joints) * spec.ntm_order if spec.ntm_joints else 0


def same_physics(a: ModelSpec, b: ModelSpec) -> bool:
    """The two layouts differ in their Fourier terms at most."""

    def bare(s: ModelSpec) -> ModelSpec:
        return replace(s, ntm_joints=(), ntm_order=2, name="")

    return bare(a) == bare(b)


def fold_fourier(
    layout: ParameterLayout, free: np.ndarray, xs: Sequence[Float]
) -> FoldCoefficients:
    """The free Fourier coefficients of every fold's solution ``xs`` (each in
    ``layout``)."""
    if not xs:
        return {}
    X = np.asarray(xs, float)
    return {
        sp.name: tuple(float(v) for v in X[:, i])
        for i, sp in enumerate(layout.specs)
        if sp.group == "ntm" and free[i]
    }


def jackknife_z2(coef: FoldCoefficients, names: Iterable[str]) -> float:
    """Mean of z^2 over the coefficients ``names``: z = mean over the folds / its
    delete-one-group jackknife standard error sqrt((k - 1) / k sum (x_i - mean)^2).
    Coefficients the folds did not move are left out; inf when none is left."""
    z2 = []
    for name in names:
        v = np.asarray(coef.get(name, ()), float)
        if v.size < 2:
            continue
        m = float(v.mean())
        se = float(np.sqrt((v.size - 1) / v.size * np.sum((v - m) ** 2)))
        if se <= 1e-12 * abs(m) or se == 0.0:
            continue
        z2.append((m / se) ** 2)
    return float(np.mean(z2)) if z2 else float("inf")


def null_z2(k: int) -> float:
    """The mean of z^2 (Student's t with k - 1 degrees of freedom) when the
    coefficients are noise: (k - 1) / (k - 3); 0 below 4 folds (not defined: no
    test)."""
    return (k - 1) / (k - 3) if k >= 4 else 0.0
