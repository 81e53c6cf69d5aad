"""What a plan promises: parameter standard deviations and the held-out accuracy.

For a design with posterior information ``M`` (prior included, :mod:`._design`), the
scaled parameters have covariance ``M^-1``, so the standard deviation of parameter k is
``s_k sqrt((M^-1)_kk)``. A held-out pose c, measured with per-axis noise ``sigma_c``, is
off the calibrated model's prediction by the measurement noise plus the prediction error,
so the expected RMS of the 3-D error over the candidates (weights ``w_c``) is

.. math:: \\mathrm{RMS}^2 = \\sum_c w_c \\left(3\\sigma_c^2 +
          \\mathrm{tr}(G_c M^{-1} G_c^T)\\right) = 3\\bar\\sigma^2 + \\mathrm{tr}(M^{-1} W),

and the noise floor (a perfect model) is ``sqrt(3) sigma-bar``. This holds to first
order, with the noise level and the priors as assumed; the study in ``docs/planning.md``
checks it against calibrations on the digital twin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.planning._design import DesignProblem
from kinecal.typing import Float

__all__ = ["Prediction", "RandomPrediction", "predict", "predict_random"]


@dataclass(frozen=True)
class Prediction:
    """Expected accuracy of one design.

    Attributes
    ----------
    n_poses : poses in the design (not counting those measured before).
    heldout_rms : expected RMS of the 3-D error on held-out candidates [m].
    model_rms : its part due to the model's uncertainty, ``sqrt(tr(M^-1 W))`` [m].
    floor : the noise floor, ``sqrt(sum_c w_c 3 sigma_c^2)`` [m].
    std : (p,) posterior standard deviation of each design parameter (SI).
    """

    n_poses: int
    heldout_rms: float
    model_rms: float
    floor: float
    std: Float

    @property
    def ratio(self) -> float:
        """Held-out RMS over the noise floor."""
        return self.heldout_rms / self.floor


@dataclass(frozen=True)
class RandomPrediction:
    """Expected accuracy of random designs of the same size (over ``draws`` draws).

    Attributes
    ----------
    heldout_rms : (draws,) expected held-out RMS of each draw [m].
    floor : noise floor [m].
    std : (p,) median over the draws of each parameter's standard deviation (SI).
    """

    n_poses: int
    heldout_rms: Float
    floor: float
    std: Float

    @property
    def mean_rms(self) -> float:
        return float(np.mean(self.heldout_rms))

    @property
    def ratio(self) -> float:
        """Mean held-out RMS of the random draws over the noise floor."""
        return self.mean_rms / self.floor


def _floor(problem: DesignProblem) -> float:
    return float(np.sqrt(3.0 * np.sum(problem.weight * problem.sigma**2)))


def predict(problem: DesignProblem, M: Float, n_poses: int) -> Prediction:
    """The expected accuracy of a design of information ``M`` (p, p), prior included."""
    A = np.linalg.inv(M)
    var_model = max(float(np.sum(A * problem.moment)), 0.0)
    floor = _floor(problem)
    std = np.sqrt(np.clip(np.diag(A), 0.0, None)) * problem.scales
    return Prediction(
        n_poses,
        float(np.sqrt(floor**2 + var_model)),
        float(np.sqrt(var_model)),
        floor,
        std,
    )


def predict_random(
    problem: DesignProblem,
    n: int,
    *,
    draws: int = 20,
    seed: int = 0,
    base: Float | None = None,
    exclude: np.ndarray | None = None,
) -> RandomPrediction:
    """The expected accuracy of ``draws`` random choices of ``n`` candidates.

    Parameters
    ----------
    base : (p, p), information before the draw (default the prior).
    exclude : (N,) bool, candidates not drawn (poses measured before).
    """
    rng = np.random.default_rng(seed)
    pool = np.flatnonzero(
        np.ones(problem.n_candidates, bool) if exclude is None else ~exclude
    )
    if not 1 <= n <= pool.size:
        raise ValueError(f"n must be between 1 and {pool.size}; got {n}.")
    rms = np.empty(draws)
    stds = np.empty((draws, problem.size))
    for k in range(draws):
        idx = rng.choice(pool, n, replace=False)
        pr = predict(problem, problem.information(idx, base), n)
        rms[k] = pr.heldout_rms
        stds[k] = pr.std
    return RandomPrediction(n, rms, _floor(problem), np.median(stds, axis=0))
