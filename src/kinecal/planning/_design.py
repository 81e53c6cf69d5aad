"""The design problem: what each candidate pose would tell about the model's parameters.

A calibration from the poses ``S`` is, to first order at a design point, a linear
Gaussian problem in the scaled parameters ``z = x / s`` (``s``: the layout's
characteristic scales). With the default maximum a posteriori calibration (Gaussian
priors of :data:`kinecal.identification.PRIOR_SIGMA`) the posterior precision is

.. math:: M(S) = P_0 + \\sum_{c \\in S} F_c^T F_c, \\qquad
          F_c = \\Sigma_c^{-1/2} J_c D, \\qquad D = \\mathrm{diag}(s),

``J_c`` the identification Jacobian of candidate c (3 rows for point and sensor data,
6 for pose data), ``Sigma_c`` its noise covariance, ``P_0 = diag((s / sigma_prior)^2)``.
The covariance of the scaled parameters is ``M^-1``. The error of the calibrated model's
prediction at candidate c has covariance ``G_c M^-1 G_c^T`` with ``G_c = J^pos_c D``
(the position rows, in metres per scaled unit): the tool point in the user frame for
tracker data, the target point mapped into the user frame for sensor data.

Parameters the candidates cannot determine are removed first, by the calibration's own
analysis (:func:`kinecal.identification.analyse_identifiability`, at its
small-compliance point); the calibration fixes them at their start values too.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal.identification import (
    PRIOR_SIGMA,
    Identifiability,
    analyse_identifiability,
)
from kinecal.models import CalibrationModel, ModelInputs
from kinecal.typing import Float

__all__ = [
    "DesignProblem",
    "design_point",
    "design_problem",
    "prior_sigma",
]

# Generic values of the compliance terms at which the design is evaluated: with lambda* = 0
# the link-moment columns vanish. lambda* is set to the characteristic scale of its kind
# (1e-4 rad/m), the link moments to a few tenths of a metre per unit payload weight (the
# identifiability analysis of the calibration uses the same moments).
_GENERIC_COMPLIANCE = 1e-4  # rad/m
# lambda* of the identifiability analysis: the small-compliance limit the calibration
# uses, where parameters that differ only through second-order effects count as redundant.
_STRUCTURAL_COMPLIANCE = 1e-7  # rad/m
# Parameters without a prior (user and tool frames) get a vague one, so the information
# of the first few poses can be inverted: 1000 characteristic sizes (1 m, 1 rad).
_VAGUE_PRIOR_SCALES = 1e3
_PRIOR_GROUPS = {
    "none": (),
    "compliance": ("load", "link"),
    "all": ("joint", "ntm", "load", "link"),
}


def design_point(model: CalibrationModel, params: Float, compliance: float) -> Float:
    """``params`` with the compliance terms at generic values.

    Parameters
    ----------
    model : CalibrationModel
    params : (P,) parameters (SI); frames and geometry are kept.
    compliance : float
        lambda* of every joint [rad/m]; the link moments become 0.3-0.5 m, link mass
        ratios 1.
    """
    g = np.array(params, dtype=np.float64)
    for i, s in enumerate(model.layout.specs):
        if s.kind == "compliance":
            g[i] = compliance
        elif s.kind == "moment":
            g[i] = 0.3 + 0.1 * (i % 3)
        elif s.kind == "ratio":
            g[i] = 1.0
    return g


def prior_sigma(
    model: CalibrationModel, priors: str = "all", scale: float = 1.0
) -> Float:
    """Prior standard deviation of each parameter (SI; ``inf``: none), as the
    calibration builds it (``CalibrationOptions.priors``; the robot file may override)."""
    if priors not in _PRIOR_GROUPS:
        raise ValueError(
            f"priors must be 'none', 'compliance' or 'all'; got {priors!r}."
        )
    from kinecal.robot import compliance_priors

    groups = _PRIOR_GROUPS[priors]
    table = {**PRIOR_SIGMA, **model.robot.prior_sigma}
    lam = compliance_priors(model.robot)  # per joint, from the link masses
    sigma = np.full(model.size, np.inf)
    for i, s in enumerate(model.layout.specs):
        if s.group in groups:
            sd = table.get((s.group, s.kind), np.inf)
            if (s.group, s.kind) == ("load", "compliance"):
                sd = lam.get(s.joint or 0, sd)
            sigma[i] = sd * scale
    return sigma


@dataclass
class DesignProblem:
    """Information and prediction blocks of every candidate, for the free parameters.

    Attributes
    ----------
    model : CalibrationModel
    params : (P,) design point (SI).
    free : (P,) bool, parameters in the design (identifiable on the candidates).
    F : (N, c, p) whitened information blocks (scaled parameters; dimensionless).
    G : (N, 3, p) prediction blocks: position of the predicted point [m] per scaled unit.
    prior_precision : (p,) precision of the scaled parameters before any pose (the
        calibration's priors; a vague one where it has none).
    has_prior : (p,) bool, the calibration holds this parameter by a prior.
    sigma : (N,) per-axis position noise of each candidate [m].
    identifiability : the analysis on all candidates.
    weight : (N,) weight of each candidate in the average prediction error (sums to 1).
    """

    model: CalibrationModel
    params: Float
    free: np.ndarray
    F: Float
    G: Float
    prior_precision: Float
    has_prior: np.ndarray
    sigma: Float
    identifiability: Identifiability
    weight: Float
    _moment: Float | None = field(default=None, repr=False)

    @property
    def n_candidates(self) -> int:
        return int(self.F.shape[0])

    @property
    def rows(self) -> int:
        """Residual components per pose (3, or 6 for pose data)."""
        return int(self.F.shape[1])

    @property
    def size(self) -> int:
        """Number of parameters in the design."""
        return int(self.F.shape[2])

    @property
    def names(self) -> list[str]:
        return [n for n, f in zip(self.model.layout.names, self.free) if f]

    @property
    def scales(self) -> Float:
        return self.model.layout.scales[self.free]

    @property
    def moment(self) -> Float:
        """``W = sum_c w_c G_c^T G_c`` (p, p) [m^2]: the average prediction error is
        ``tr(M^-1 W)``."""
        if self._moment is None:
            Gw = self.G * np.sqrt(self.weight)[:, None, None]
            flat = Gw.reshape(-1, self.size)
            self._moment = flat.T @ flat
        return self._moment

    def information(self, rows: np.ndarray, base: Float | None = None) -> Float:
        """``M`` (p, p) of the candidates ``rows`` (indices, repeats allowed), on top of
        ``base`` (default: the prior precision)."""
        Fs = self.F[np.asarray(rows, np.intp)].reshape(-1, self.size)
        M = Fs.T @ Fs
        if base is None:
            M[np.diag_indices_from(M)] += self.prior_precision
        else:
            M += base
        return M


def design_problem(
    model: CalibrationModel,
    params: Float,
    inputs: ModelInputs,
    sigma: Float | float,
    *,
    sigma_rot: Float | float | None = None,
    priors: str = "all",
    prior_scale: float = 1.0,
    compliance: float | None = _GENERIC_COMPLIANCE,
    drop_tol: float = 1e-6,
    weight: Float | None = None,
    structural: Float | None = None,
) -> DesignProblem:
    """Build the design problem of ``model`` over the candidate poses ``inputs``.

    Parameters
    ----------
    model : CalibrationModel
        The model to calibrate, its spec fitted to the data (``cam_rotation=False`` for
        position-only data).
    params : (P,) nominal parameters with the set-up's frames (SI). Compliance terms are
        replaced by generic values (:func:`design_point`) unless ``compliance`` is None.
    inputs : ModelInputs of the N candidates (``p_cam``: the target in the cam frame for
        sensor data).
    sigma : float or (N,)
        Per-axis position noise [m].
    sigma_rot : float or (N,), optional
        Orientation noise [rad]: pose (6-D) data; None for point and sensor data.
    priors, prior_scale : the calibration's priors (``CalibrationOptions``).
    compliance : float or None
        lambda* of the design point [rad/m]; None keeps ``params`` (a calibrated model).
    drop_tol : identifiability tolerance (as the calibration's).
    weight : (N,), optional
        Weight of each candidate in the average prediction error (default equal).
    structural : (P,), optional
        Point of the identifiability analysis (default: ``params`` with lambda* = 1e-7).

    Raises
    ------
    ValueError
        Shapes or noise values that do not fit.
    """
    N = inputs.n
    if N < 1:
        raise ValueError("need at least one candidate pose; got 0.")
    sig = np.broadcast_to(np.asarray(sigma, np.float64), (N,)).copy()
    if not np.all(np.isfinite(sig) & (sig > 0)):
        raise ValueError(f"sigma must be positive and finite; got {sigma!r}.")
    x = np.asarray(params, np.float64)
    x_design = x if compliance is None else design_point(model, x, compliance)
    x_struct = (
        design_point(model, x, _STRUCTURAL_COMPLIANCE)
        if structural is None
        else np.asarray(structural, np.float64)
    )
    scales = model.layout.scales
    Fs, _ = _whitened(model, x_struct, inputs, sig, sigma_rot)
    Fd, Jpos = _whitened(model, x_design, inputs, sig, sigma_rot)
    P = model.size
    J_struct = np.moveaxis(Fs, 2, 0).reshape(P, -1).T  # (m, P)
    if J_struct.shape[0] < P:  # fewer rows than parameters: zero rows change nothing
        J_struct = np.vstack([J_struct, np.zeros((P - J_struct.shape[0], P))])
    ident = analyse_identifiability(
        J_struct,
        model.layout,
        np.ones(P, bool),
        drop_tol=drop_tol,
    )
    free = ident.free
    sc = scales[free]
    F = np.ascontiguousarray(Fd[:, :, free] * sc)
    G = np.ascontiguousarray(Jpos[:, :, free] * sc)
    ps = prior_sigma(model, priors, prior_scale)[free]
    has_prior = np.isfinite(ps)
    prec = np.where(has_prior, (sc / np.where(has_prior, ps, 1.0)) ** 2, 0.0)
    prec[~has_prior] = 1.0 / _VAGUE_PRIOR_SCALES**2
    w = _average_weights(weight, N)
    return DesignProblem(model, x_design, free, F, G, prec, has_prior, sig, ident, w)


def _whitened(
    model: CalibrationModel,
    point: Float,
    inputs: ModelInputs,
    sig: Float,
    sigma_rot: Float | float | None,
) -> tuple[Float, Float]:
    """``(whitened Jacobian (N, c, P), position Jacobian (N, 3, P))`` at ``point``:
    positions over ``sig``, and orientations over ``sigma_rot`` for pose data."""
    N = inputs.n
    pose = sigma_rot is not None
    out = model.evaluate(point, inputs, orientation=pose, jacobian=True)
    assert out.J_p is not None
    Jp = out.J_p  # (N, 3, P)
    if not pose:
        return Jp / sig[:, None, None], Jp
    assert out.J_w is not None
    sr = np.broadcast_to(np.asarray(sigma_rot, np.float64), (N,))
    if not np.all(np.isfinite(sr) & (sr > 0)):
        raise ValueError(f"sigma_rot must be positive and finite; got {sigma_rot!r}.")
    Jw = np.concatenate([Jp / sig[:, None, None], out.J_w / sr[:, None, None]], axis=1)
    return Jw, Jp


def _average_weights(weight: Float | None, N: int) -> Float:
    """Weights (N,) of the candidates in the average prediction error, summing to 1."""
    if weight is None:
        return np.full(N, 1.0 / N)
    w = np.asarray(weight, np.float64).reshape(N)
    if np.any(w < 0) or w.sum() <= 0:
        raise ValueError("weight must be non-negative with a positive sum.")
    return w / w.sum()
