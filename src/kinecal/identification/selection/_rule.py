"""The rule of ``--model auto``: which candidate a scored table chooses.

The smallest candidate whose validation RMS is within :data:`_SE_FACTOR` standard errors
of the best (the error taken on the paired per-fold log ratios of the RMS: the folds are
the same for every candidate), and 1 %, among those whose Fourier terms' coefficients
are reproducible across the folds and whose Fourier series is not cut below orders that
are (:mod:`._fourier`; docs/theory.md, "Accuracy on a new session").
"""

from __future__ import annotations

from typing import Protocol, TypeVar

import numpy as np

from kinecal.identification.selection._fourier import (
    Scored,
    fourier_z2,
    null_z2,
    truncation_z2,
)

__all__ = ["choose_candidate"]


class Row(Scored, Protocol):
    """What the rule needs of a candidate (:class:`._select.Candidate`)."""

    prior_scale: float
    cv_se_mm: float
    chosen: bool


Candidate = TypeVar("Candidate", bound=Row)


def _within_one_se(c: Row, best: Row) -> bool:
    """One-standard-error rule on the paired fold ratios (with a factor
    :data:`_SE_FACTOR`).

    All candidates share the folds, so the fold-to-fold spread (which pose happened to be
    in which fold) is common to them; the standard error of the per-fold *differences*
    to the best candidate is the one that says whether ``c`` is really worse. The
    differences are taken as log ratios of the fold RMS: region folds differ in
    difficulty (2.7-9.5 mm on the shipped TIAGo set), and an absolute difference lets
    the hardest region alone decide. A gain below :data:`_PRACTICAL` of the RMS does not
    count either: when every candidate predicts alike (the data hold no compliance), the
    paired error can be smaller than what separates them by chance, and extra terms must
    earn their place.
    """
    a, b = np.asarray(c.fold_rms_mm), np.asarray(best.fold_rms_mm)
    if a.size != b.size or a.size < 2 or np.any(a <= 0) or np.any(b <= 0):
        margin = _PRACTICAL * best.cv_rms_mm
        se = best.cv_se_mm if np.isfinite(best.cv_se_mm) else 0.0
        return c.cv_rms_mm <= best.cv_rms_mm + max(_SE_FACTOR * se, margin)
    d = np.log(a / b)
    se_d = float(d.std(ddof=1) / np.sqrt(d.size))
    return float(d.mean()) <= max(_SE_FACTOR * se_d, np.log1p(_PRACTICAL))


# A larger model must predict at least this much better (relative RMS) to be chosen.
_PRACTICAL = 0.01

# How many standard errors of the paired fold differences a larger model must gain: 1.75
# rather than the textbook 1 (issue 31; nested cross-validation, the selection inside
# every fold, region folds): on the shipped TIAGo set 1 chose compliance or transmission
# terms in 3 of 5 folds and cost 7 % against the kinematic model, 1.5 cost 1.7 % (5-fold)
# and 4.2 % (leave-one-out), 1.75 1.3 % and 0.7 %, 2 chose the kinematic model in every
# fold; on the region-shift twin (6 seeds) 1.75 stays within 1.091x of the best fixed
# model, 2 reaches 1.112x. Preferring fewer Fourier terms among the eligible candidates
# made no difference on the real sets and cost up to 1.185x on the twin (whose truth has
# transmission errors): the choice is by size. With the fold differences taken as log
# ratios (:func:`_within_one_se`, same factor) rather than in mm: TIAGo 5-fold 1.3 % ->
# 0.0 % against the kinematic model, leave-one-out 0.7 % -> 0.03 %; UR10e unchanged
# (kinematic); FR3 5-fold 1.172 -> 1.184 mm (kinematic 1.247), leave-one-out 1.168 ->
# 1.166; the twin's six seeds unchanged (at most 1.091x). In mm, 1.8-1.85 would mend
# TIAGo's leave-one-out only, 1.9 both (twin 1.096x, FR3 leave-one-out +0.5 %), 1.95 and
# up cost 1.112x on the twin (log ratios: from 1.8). The decisive folds sit at 1.9 paired
# standard errors on TIAGo and on the twin alike: no factor separates them cleanly.
_SE_FACTOR = 1.75


def choose_candidate(cands: list[Candidate]) -> Candidate:
    """The candidate the rule of :func:`select_model` chooses from a scored table
    (marked ``chosen``): the smallest within :data:`_SE_FACTOR` paired standard errors
    of the best, but none whose Fourier terms are not reproducible across the folds
    (:func:`_fourier_reproducible`) and none whose series is cut below reproducible
    orders (:func:`_cut_short`); without those, the best of the others may admit
    smaller candidates too."""
    kept = [c for c in cands if _fourier_reproducible(c, cands)]
    kept = [c for c in kept if not _cut_short(c, kept)]
    eligible = eligible_among(cands, kept)
    # The smallest model; among equal sizes the strongest priors (the simplest fit).
    chosen = min(eligible, key=lambda c: (c.size, -1.0 / c.prior_scale, c.cv_rms_mm))
    chosen.chosen = True
    return chosen


def eligible_among(cands: list[Candidate], kept: list[Candidate]) -> list[Candidate]:
    """The candidates within :data:`_SE_FACTOR` paired standard errors of the best;
    where ``kept`` (a sublist) leaves some out, those of ``kept`` that were, or are
    within it of the best of ``kept``."""
    best = min(cands, key=lambda c: c.cv_rms_mm)
    eligible = [c for c in cands if _within_one_se(c, best)]
    if len(kept) < len(cands):
        best = min(kept, key=lambda c: c.cv_rms_mm)
        eligible = [
            c for c in kept if any(c is e for e in eligible) or _within_one_se(c, best)
        ]
    return eligible


def _fourier_reproducible(c: Row, cands: list[Candidate]) -> bool:
    """Whether the Fourier terms ``c`` has beyond each candidate with the same physical
    terms and fewer Fourier terms are reproducible across the folds: the mean z^2 of
    their coefficients (delete-one-fold jackknife, :func:`._fourier.fourier_z2`) at
    least what noise gives (:func:`._fourier.null_z2`: 2 for 5 folds)."""
    return fourier_z2(c, cands) >= null_z2(len(c.fold_rms_mm))


def _cut_short(c: Row, cands: list[Candidate]) -> bool:
    """Whether ``c``'s Fourier series stops below orders that a candidate with the same
    physical terms has reproducibly (:func:`._fourier.truncation_z2` at least
    :func:`._fourier.null_z2`): it aliases them and does not carry over."""
    floor = null_z2(len(c.fold_rms_mm))
    return floor > 0.0 and truncation_z2(c, cands) >= floor
