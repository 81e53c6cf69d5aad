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
from typing import Protocol

import numpy as np

from kinecal.models import ModelSpec, ParameterLayout
from kinecal.typing import Float

__all__ = [
    "FoldCoefficients",
    "Scored",
    "fold_fourier",
    "fourier_notes",
    "fourier_terms",
    "fourier_z2",
    "jackknife_z2",
    "null_z2",
    "same_physics",
    "truncation_z2",
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


class Scored(Protocol):
    """What the test needs of a candidate (:class:`._select.Candidate`)."""

    label: str
    spec: ModelSpec
    size: int
    cv_rms_mm: float
    fold_rms_mm: tuple[float, ...]
    fold_fourier: FoldCoefficients


def fourier_z2(c: Scored, cands: Sequence[Scored]) -> float:
    """The least mean z^2 (:func:`jackknife_z2`) of the Fourier terms ``c`` has beyond
    a candidate with the same physical terms and fewer Fourier terms (inf: none, or no
    fold coefficients)."""
    n = fourier_terms(c.spec)
    if n == 0 or not c.fold_fourier:
        return float("inf")
    return min(
        (
            jackknife_z2(
                c.fold_fourier, [k for k in c.fold_fourier if k not in o.fold_fourier]
            )
            for o in cands
            if fourier_terms(o.spec) < n and same_physics(o.spec, c.spec)
        ),
        default=float("inf"),
    )


def truncation_z2(c: Scored, cands: Sequence[Scored]) -> float:
    """The largest mean z^2 (:func:`jackknife_z2`) of the Fourier terms a candidate with
    the same physical terms and more Fourier terms, validated at least as well, has
    beyond ``c`` (0: ``c`` has no Fourier terms, or there is no such candidate with
    fold coefficients).

    A series cut below harmonics the arm has (order 1 where order 2 is reproducible
    and predicts the held-out regions no worse) aliases them into its lower orders over
    the arc of each joint the poses cover: its coefficients follow the pose
    distribution, and it predicts a new one worse than the whole series or none
    (docs/theory.md, "Accuracy on a new session")."""
    n = fourier_terms(c.spec)
    if n == 0:
        return 0.0
    z2 = [
        jackknife_z2(
            o.fold_fourier, [k for k in o.fold_fourier if k not in c.fold_fourier]
        )
        for o in cands
        if fourier_terms(o.spec) > n
        and same_physics(o.spec, c.spec)
        and o.fold_fourier
        and o.cv_rms_mm <= c.cv_rms_mm
    ]
    return max((z for z in z2 if np.isfinite(z)), default=0.0)


# A smaller candidate left out within this of the chosen one's RMS gets a note.
_AS_WELL = 1.01


def fourier_notes(cands: Sequence[Scored], chosen: Scored) -> list[str]:
    """A note on the candidates left out because their Fourier coefficients are not
    reproducible across the folds (those that validated better than ``chosen``), or
    because their series is cut below reproducible orders (:func:`truncation_z2`: the
    smaller ones that validated within :data:`_AS_WELL` of it); those with the same
    figures in one note."""
    floor = null_z2(len(chosen.fold_rms_mm))
    left: dict[tuple[str, str, bool], list[str]] = {}
    for c in sorted(cands, key=lambda c: c.cv_rms_mm):
        if c.cv_rms_mm >= _AS_WELL * chosen.cv_rms_mm or floor == 0.0:
            continue
        z2, cut = fourier_z2(c, cands), truncation_z2(c, cands)
        if (z2 < floor and c.cv_rms_mm < chosen.cv_rms_mm) or (
            cut >= floor and c.size < chosen.size
        ):
            key = (
                f"{c.cv_rms_mm:.4f}",
                f"{z2 if z2 < floor else cut:.2f}",
                z2 >= floor,
            )
            labels = left.setdefault(key, [])
            if c.label not in labels:  # (one note per layout, not per prior strength)
                labels.append(c.label)
    return [
        f"{', '.join(labels)}: validated {'as well' if cut else 'better'} ({rms} mm "
        f"against "
        f"{chosen.cv_rms_mm:.4f}) but "
        + (
            f"the higher Fourier orders it leaves out are reproducible (mean z^2 {z2}; "
            f"noise gives {floor:.2f}): a series cut short follows the pose "
            "distribution. Not chosen"
            if cut
            else f"the Fourier coefficients change with the region left out (mean z^2 "
            f"{z2}; noise gives {floor:.2f}): not chosen, as such terms did not carry "
            "over to a new session"
        )
        + ". A second session scored with evaluate --refit user,tool tells."
        for (rms, z2, cut), labels in left.items()
    ]
