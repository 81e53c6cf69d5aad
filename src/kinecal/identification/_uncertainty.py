"""The last stages: uncertainty of the estimate, and what is worth telling about it.

:class:`Uncertainty` computes ``cov = s0^2 (J^T W J + P)^-1`` at the solution (Eq. (T-3)),
the standard deviations and ``s0``. :class:`Diagnose` reports rows with improbable errors
(``outliers``), parameters their prior determines (``prior_dominated``), parameters
without a prior the poses hardly determine (``loose_parameters``) and a high ratio of
parameters to residuals (``overfit_risk``).
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace

import numpy as np

from kinecal.identification._diagnostics import Diagnostic, Outlier
from kinecal.identification._lm import loss_weights, normal_equations, psd_inverse
from kinecal.identification._measurements import Measurements
from kinecal.identification._priors import build_prior
from kinecal.identification._problem import Problem, State
from kinecal.identification._stages import robust_sigma
from kinecal.typing import Float

__all__ = ["Diagnose", "Uncertainty", "chi2_isf", "find_outliers"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Uncertainty:
    """Covariance ``s0^2 (J^T W J + P)^-1`` of the free parameters at the solution
    (``W``: robust row weights, ``P``: prior precision; Eq. (T-3)), their standard
    deviations and the a-posteriori standard deviation of unit weight ``s0``."""

    name: str = "uncertainty"

    def __call__(self, problem: Problem, state: State) -> State:
        cm, lm = state.model, state.lm
        fidx = np.flatnonzero(state.free)
        scales = cm.layout.scales[fidx]
        blk = problem.evaluations(cm, state.x, state.weights, jacobian=True)
        assert blk.J is not None
        wr = loss_weights(np.sum(blk.r**2, axis=1) / lm.f_scale**2, lm.loss)[1]
        dof = problem.n_residuals - fidx.size
        sigma0 = float(np.sqrt(np.sum(wr[:, None] * blk.r**2) / max(dof, 1)))
        A, _ = normal_equations(
            blk.r, blk.J, fidx, scales, None if lm.loss == "linear" else np.sqrt(wr)
        )
        prior = state.active_prior()
        if prior is not None:
            A = A + np.diag(prior.precision[fidx] * scales**2)
        cov = np.zeros((cm.size, cm.size))
        found = []
        try:
            cov_f = sigma0**2 * psd_inverse(A, 1e-14) * np.outer(scales, scales)
            cov[np.ix_(fidx, fidx)] = cov_f  # Eq. (T-3)
        except np.linalg.LinAlgError:
            found.append(
                Diagnostic(
                    "no_covariance",
                    "the normal matrix could not be inverted; no standard deviations.",
                    stage=self.name,
                )
            )
        std = np.full(cm.size, np.nan)
        std[fidx] = np.sqrt(np.clip(np.diag(cov)[fidx], 0.0, None))
        return state.but(covariance=cov, std=std, sigma0=sigma0).note(*found)


@dataclass(frozen=True)
class Diagnose:
    """Findings about the solution: ``outliers`` (rows improbable under the fitted noise,
    by their file rows), ``prior_dominated``, ``loose_parameters`` and ``overfit_risk``."""

    name: str = "diagnose"

    def __call__(self, problem: Problem, state: State) -> State:
        cm, opts = state.model, problem.options
        blk = problem.evaluations(cm, state.x, state.weights)
        found = []
        outliers = find_outliers(blk.r, blk.raw_position, problem.meas, opts.outlier_p)
        if outliers:
            what = (
                "down-weighted" if opts.loss != "linear" else "kept (use --loss huber)"
            )
            found.append(
                Diagnostic(
                    "outliers",
                    f"{len(outliers)} rows look like outliers; {what}: rows "
                    + ", ".join(str(o.row) for o in outliers[:10])
                    + (" ..." if len(outliers) > 10 else "")
                    + ".",
                    rows=tuple(o.row for o in outliers),
                    stage=self.name,
                )
            )
        fidx = np.flatnonzero(state.free)
        std = state.std if state.std is not None else np.full(cm.size, np.nan)
        prior = state.active_prior()
        if prior is not None:
            # Terms the data barely inform: the posterior is (almost) the prior.
            weak = [
                cm.layout.names[i]
                for i in fidx
                if np.isfinite(prior.sigma[i]) and std[i] > 0.7 * prior.sigma[i]
            ]
            if weak:
                found.append(
                    Diagnostic(
                        "prior_dominated",
                        f"{len(weak)} parameters are determined mostly by their prior, "
                        f"not by the data: {', '.join(weak[:8])}"
                        + (" ..." if len(weak) > 8 else "")
                        + ".",
                        parameters=tuple(weak),
                        stage=self.name,
                    )
                )
        assert state.prior is not None and state.x_registered is not None
        loose = _loose_parameters(problem, state, std, fidx)
        if loose:
            found.append(
                Diagnostic(
                    "loose_parameters",
                    f"{len(loose)} parameters without a prior are hardly determined by "
                    "these poses: their standard deviation exceeds the size the default "
                    "priors allow (--priors all): "
                    + ", ".join(f"{name} ({ratio:.3g}x)" for name, ratio in loose[:8])
                    + (f" and {len(loose) - 8} more" if len(loose) > 8 else "")
                    + ".",
                    parameters=tuple(name for name, _ in loose),
                    stage=self.name,
                )
            )
        ratio = fidx.size / problem.n_residuals
        if ratio > 0.2:
            found.append(
                Diagnostic(
                    "overfit_risk",
                    f"{fidx.size} parameters from {problem.n_residuals} residuals "
                    f"({ratio:.0%}): results may overfit; validate on other poses.",
                    stage=self.name,
                )
            )
        if state.identifiability is not None:
            for d in state.identifiability.dropped:
                log.info("unidentifiable: %s", d.describe())
        return state.but(outliers=tuple(outliers)).note(*found)


def _loose_parameters(
    problem: Problem, state: State, std: Float, fidx: np.ndarray
) -> list[tuple[str, float]]:
    """Estimated parameters without a prior (``sigma`` infinite) whose standard
    deviation exceeds the prior ``--priors all`` would give them (their plausible size),
    as ``(name, std / that prior)``, largest first: plain least squares leaves them to
    the noise."""
    assert state.prior is not None and state.x_registered is not None
    cm = state.model
    sigma = state.prior.sigma
    plausible = build_prior(
        cm, state.x_registered, replace(problem.options, priors="all")
    ).sigma
    out = [
        (cm.layout.names[i], float(std[i] / plausible[i]))
        for i in fidx
        if not np.isfinite(sigma[i])
        and np.isfinite(plausible[i])
        and std[i] > plausible[i]
    ]
    return sorted(out, key=lambda item: -item[1])


def chi2_isf(df: int, p: float) -> float:
    """Chi-square quantile with ``P(X > x) = p`` for an integer number of degrees of freedom.

    The survival function has a closed form for integer ``df`` (a Poisson sum for even
    ``df``, erfc plus a half-integer sum for odd); bisection inverts it to round-off.
    Written out so calibration does not import scipy.special (0.2 s at start-up).
    """
    if df < 1 or not 0.0 < p < 1.0:
        raise ValueError(f"need df >= 1 and 0 < p < 1; got df={df}, p={p}.")

    def sf(x: float) -> float:
        h = 0.5 * x
        if df % 2 == 0:
            terms = (h**i / math.factorial(i) for i in range(df // 2))
            return math.exp(-h) * math.fsum(terms)
        terms = (h ** (i - 0.5) / math.gamma(i + 0.5) for i in range(1, (df + 1) // 2))
        return math.erfc(math.sqrt(h)) + math.exp(-h) * math.fsum(terms)

    lo, hi = 0.0, max(2.0 * df, 1.0)
    while sf(hi) > p:
        lo, hi = hi, 2.0 * hi
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        lo, hi = (mid, hi) if sf(mid) > p else (lo, mid)
    return 0.5 * (lo + hi)


def find_outliers(
    r: Float, e_pos: Float, meas: Measurements, p: float
) -> list[Outlier]:
    """Rows whose whitened error norm is beyond the chi quantile of probability ``p``
    under the robust noise estimate, most improbable first."""
    c = r.shape[1]
    sigma = robust_sigma(r)
    if sigma <= 0:
        return []
    z = np.linalg.norm(r, axis=1) / sigma  # Eq. (T-4)
    thr = math.sqrt(chi2_isf(c, p))  # chi-square quantile: P(X > thr^2) = p
    bad = np.flatnonzero(z > thr)
    err = np.linalg.norm(e_pos, axis=1) * 1e3
    order = bad[np.argsort(-z[bad])]
    return [Outlier(int(meas.rows[i]), float(err[i]), float(z[i])) for i in order]
