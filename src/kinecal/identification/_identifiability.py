"""Identifiability: which parameters the poses determine, and how well.

The identification Jacobian is scaled by each parameter's characteristic size (so mm and
rad columns compare) and its columns normalised. Columns are then taken in a fixed order
of preference (user and cam frames, joint geometry, compliance, transmission terms; d and
the constant k0 last) and each is projected on the span of the ones kept before it
(Gram-Schmidt in that order, computed as the Cholesky factor of the normal matrix, which is
the QR factor without pivoting). A column whose remaining part is
below ``drop_tol`` of its norm is a combination of kept ones: it is unidentifiable, fixed
at its starting value, and reported with its partners. Decisions use relative tolerances
only (``|R_kk| / |j_k|``), never absolute ones.

Known cases it finds (DESIGN §4): k0 of J1-J3 against the joint offsets and the base
rotation; lambda1* when joint 1 is parallel to gravity; d on parallel axes; the link
moment s1 against the first NTM harmonic of J2 on a level base.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal._record import MutableRecord, Record
from kinecal.models import ParameterLayout
from kinecal.typing import Float

__all__ = [
    "DroppedParameter",
    "Identifiability",
    "analyse_identifiability",
    "correlation_from_covariance",
    "grouped_dropped",
    "identifiability_from_normal",
    "priority_order",
]

_GROUP_RANK = {"base": 0, "cam": 1, "joint": 2, "load": 3, "link": 4, "ntm": 5}
_JOINT_FIELD_RANK = {"theta_offset": 0, "alpha": 1, "a": 2, "beta": 3, "d": 4}


def priority_order(layout: ParameterLayout) -> np.ndarray:
    """Indices of ``layout`` from most to least preferred to keep."""

    def key(i: int) -> tuple[int, int, int]:
        s = layout.specs[i]
        if s.group == "joint":
            sub = _JOINT_FIELD_RANK.get(s.field, 5)
        elif s.group == "ntm":
            sub = 1 if s.field == "k0" else 0
        else:
            sub = 0
        return (_GROUP_RANK.get(s.group, 9), sub, i)

    return np.array(sorted(range(layout.size), key=key), dtype=np.intp)


@dataclass(frozen=True, eq=False, repr=False)
class DroppedParameter(Record):
    """An unidentifiable parameter and the kept parameters it is a combination of."""

    name: str
    fraction: float
    partners: list[tuple[str, float]]

    def describe(self) -> str:
        if not self.partners:
            return f"{self.name} does not affect the measurements"
        terms = " ".join(f"{c:+.3g}·{n}" for n, c in self.partners)
        return f"{self.name} ≈ {terms} (in characteristic units)"


def _expected_reason(d: DroppedParameter) -> str | None:
    """Why ``d`` is unidentifiable by the model's construction, or None (a finding
    about these poses).

    * a constant transmission term ``k0``: a zero offset of the joint;
    * ``joint<K>.d`` equal to +-1 x another joint's d: parallel axes (the common
      normal's position along them is arbitrary);
    * a joint compliance that does not act at all: no gravity torque about that joint
      (a vertical first axis);
    * a transmission harmonic that is a combination of compliance or link terms only:
      it acts like gravity on a level base.
    """
    fld = d.name.partition(".")[2]
    kinds = {n.partition(".")[2] for n, _ in d.partners}
    if fld == "k0":
        return "a constant transmission error is a zero offset"
    if (
        fld == "d"
        and len(d.partners) == 1
        and kinds == {"d"}
        and abs(abs(d.partners[0][1]) - 1.0) < 1e-3
    ):
        return "parallel axes: d slides along them"
    if fld == "lambda" and not d.partners:
        return "no gravity torque about the joint"
    gravity = all(n.startswith("link") or n.endswith(".lambda") for n, _ in d.partners)
    if fld[:2] in ("ka", "kb") and d.partners and gravity:
        return "a harmonic indistinguishable from the link weights"
    return None


def grouped_dropped(dropped: list[DroppedParameter]) -> list[str]:
    """The unidentifiable parameters in words: those expected by construction (see
    :func:`_expected_reason`) on one line by reason, the general link model's body terms
    (only combinations of the masses and first moments act on the joints) on another,
    and every other one (a finding about these poses) on a line of its own."""
    expected: dict[str, list[str]] = {}
    links: list[str] = []
    lines: list[str] = []
    for d in dropped:
        if d.name.startswith("link"):
            links.append(d.name)
            continue
        why = _expected_reason(d)
        if why is None:
            lines.append(f"unidentifiable: {d.describe()}")
        else:
            expected.setdefault(why, []).append(d.name)
    head: list[str] = []
    if expected:
        parts = "; ".join(f"{', '.join(n)} ({why})" for why, n in expected.items())
        head.append(
            "not identifiable by construction (held at their start values): " + parts
        )
    if links:
        head.append(
            f"link model: {len(links)} body terms act only together with others (as "
            "expected: the joints feel combinations of the link masses and first "
            "moments; held at the robot file's values): " + ", ".join(links)
        )
    return head + lines


@dataclass(eq=False, repr=False)
class Identifiability(MutableRecord):
    """Result of :func:`analyse_identifiability`.

    Attributes
    ----------
    names : list of str, every parameter of the layout.
    candidate : (P,) bool, parameters that were to be estimated.
    free : (P,) bool, parameters that are estimated (candidate minus unidentifiable).
    fraction : (P,) remaining fraction ``|R_kk| / |j_k|`` of each candidate column (NaN
        for non-candidates).
    dropped : unidentifiable parameters with their partners.
    weak : (name, fraction) of kept parameters below ``weak_tol``: poorly determined.
    singular_values : scaled, column-normalised singular values of the free columns.
    condition_number : ratio of the largest to the smallest of them.
    """

    names: list[str]
    candidate: np.ndarray
    free: np.ndarray
    fraction: Float
    dropped: list[DroppedParameter] = field(default_factory=list)
    weak: list[tuple[str, float]] = field(default_factory=list)
    singular_values: Float = field(default_factory=lambda: np.zeros(0))
    condition_number: float = float("nan")

    @property
    def rank(self) -> int:
        return int(self.free.sum())

    def summary(self) -> list[str]:
        """Findings in words, one line each."""
        lines = [
            f"{self.rank} of {int(self.candidate.sum())} parameters identifiable; "
            f"condition number {self.condition_number:.3g} (scaled, normalised columns)."
        ]
        lines += grouped_dropped(self.dropped)
        lines += [
            f"poorly determined: {n} (independent fraction {f:.1e})"
            for n, f in self.weak
        ]
        return lines


def analyse_identifiability(
    J: Float,
    layout: ParameterLayout,
    candidate: np.ndarray,
    *,
    drop_tol: float = 1e-6,
    weak_tol: float = 1e-3,
) -> Identifiability:
    """Find the unidentifiable and poorly identifiable parameters of a Jacobian.

    Parameters
    ----------
    J : (m, P) whitened identification Jacobian (rows: residual components).
    layout : ParameterLayout of the P columns.
    candidate : (P,) bool, parameters meant to be estimated.
    drop_tol : float
        Relative remaining norm below which a column is unidentifiable.
    weak_tol : float
        Relative remaining norm below which a kept column is reported as poorly determined.

    The analysis runs on the normal matrix ``Jᵀ J`` (:func:`identifiability_from_normal`):
    in exact arithmetic its Cholesky factor in the order of preference is the triangular
    factor of the QR decomposition of the scaled, normalised columns, and a fraction
    ``|R_kk|`` is accurate to about ``1e-14 / (2 f)``, far below the tolerances. On a
    2000-pose full model it takes 1.4 ms where the Householder QR of J took 9 ms.
    """
    J = np.asarray(J, np.float64)
    return identifiability_from_normal(
        J.T @ J, layout, candidate, drop_tol=drop_tol, weak_tol=weak_tol
    )


def identifiability_from_normal(
    A: Float,
    layout: ParameterLayout,
    candidate: np.ndarray,
    *,
    drop_tol: float = 1e-6,
    weak_tol: float = 1e-3,
) -> Identifiability:
    """:func:`analyse_identifiability` from the normal matrix ``A = Jᵀ J`` (P, P).

    Also for data too large to hold ``J`` (:mod:`._blocks`). The scaled,
    column-normalised normal matrix is factored by Cholesky in the order of preference,
    ``Rᵀ R = A_n``: in exact arithmetic ``R`` is the triangular factor of the QR
    decomposition of the columns, so ``|R_kk|``, the partners and the singular values
    are those of Gram-Schmidt in that order. A column found unidentifiable is left out
    of the elimination of the columns after it, so a later column's fraction is its
    part the kept columns cannot explain. (A Householder QR of J turns a dropped
    column's remainder, typically of round-off size, into a unit direction and projects
    the later columns on it too: their fractions come out smaller there, by a few
    percent up to half on the shipped examples, the decisions alike;
    tests/identification/test_issue_26_blocks.py.) A fraction is accurate to about
    ``1e-14 / (2 f)`` here, far below the tolerances.
    """
    candidate = np.asarray(candidate, dtype=bool)
    P = layout.size
    As = np.asarray(A, np.float64) * np.outer(layout.scales, layout.scales)
    norms = np.sqrt(np.clip(np.diag(As), 0.0, None))
    order = [i for i in priority_order(layout) if candidate[i]]
    fraction = np.full(P, np.nan)
    free = np.zeros(P, dtype=bool)
    if not order:
        return Identifiability(layout.names, candidate, free, fraction)
    o = np.array(order)
    big = max(float(norms[o].max()), 1e-300)
    zero = norms[o] <= 1e-12 * big
    nz = np.where(zero, 1.0, norms[o])
    An = As[np.ix_(o, o)] / np.outer(nz, nz)
    An[zero, :] = 0.0
    An[:, zero] = 0.0
    k = len(order)
    R = np.zeros((k, k))
    S = An.copy()  # Schur complement of the columns kept so far
    kept_pos: list[int] = []
    kept: list[int] = []
    dropped: list[DroppedParameter] = []
    weak: list[tuple[str, float]] = []
    for c, i in enumerate(order):
        f = 0.0 if zero[c] else float(np.sqrt(max(S[c, c], 0.0)))
        fraction[i] = f
        if f < drop_tol:
            partners: list[tuple[str, float]] = []
            if not zero[c] and kept:
                Rk = R[np.ix_(kept_pos, kept_pos)]
                # Least squares of column c on the kept ones: Rk^T Rk coef = A_n[kept, c].
                y = np.linalg.solve(Rk.T, An[kept_pos, c])
                partners = _partners(layout, np.linalg.solve(Rk, y), norms, i, kept)
            dropped.append(DroppedParameter(layout.names[i], f, partners))
            continue
        R[c, c] = f
        R[c, c + 1 :] = S[c, c + 1 :] / f
        S[c + 1 :, c + 1 :] -= np.outer(R[c, c + 1 :], R[c, c + 1 :])
        kept_pos.append(c)
        kept.append(i)
        if f < weak_tol:
            weak.append((layout.names[i], f))
    free[kept] = True
    sv, cond = _spectrum(R[np.ix_(kept_pos, kept_pos)])
    return Identifiability(
        layout.names, candidate, free, fraction, dropped, weak, sv, cond
    )


def _partners(
    layout: ParameterLayout, coef: np.ndarray, norms: Float, i: int, kept: list[int]
) -> list[tuple[str, float]]:
    """The kept columns that explain column ``i`` most (up to four), with their
    coefficients in the columns' characteristic units (``coef`` is for the normalised
    columns)."""
    coef = coef * norms[i] / norms[kept]
    top = np.argsort(-np.abs(coef))[:4]
    return [
        (layout.names[kept[t]], float(coef[t]))
        for t in top
        if abs(coef[t]) > 1e-3 * np.abs(coef).max()
    ]


def _spectrum(R_kept: Float) -> tuple[Float, float]:
    """Singular values of the kept columns' triangular factor and its condition number
    (none and NaN when no column is kept)."""
    if R_kept.shape[1] == 0:
        return np.zeros(0), float("nan")
    sv = np.asarray(np.linalg.svd(R_kept, compute_uv=False), np.float64)
    return sv, float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")


def correlation_from_covariance(cov: Float) -> Float:
    """Correlation matrix of a covariance matrix (zero rows give zero correlations)."""
    d = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        C = cov / np.outer(d, d)
    C[~np.isfinite(C)] = 0.0
    return C
