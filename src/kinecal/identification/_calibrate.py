"""Three-stage identification (paper Sec. 4, Fig. 6), from nominal kinematics alone.

0. Registration: closed-form user and cam frames (:mod:`._init`), refined by LM with the
   nominal kinematics: the "before calibration" state.
1. Stage 1: the unified kinematic parameters (30, or 27 for position data).
2. Stage 2: transmission-error Fourier coefficients by linear least squares, either from
   the stage-1 residuals projected to joints 1-3 (Eq. 29, the paper) or directly on the
   position residuals (default).
3. Stage 3: every parameter together, started from stages 1-2.

Before stage 1 the identifiability analysis fixes the parameters the poses cannot
determine, so the result is unique. Standard deviations come from the covariance
``s0^2 (J^T W J)^-1`` at the solution.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._stats import median
from kinecal.errors import DataError, IdentifiabilityError
from kinecal.identification._calibrated import CalibratedModel
from kinecal.identification._identifiability import (
    Identifiability,
    analyse_identifiability,
)
from kinecal.identification._init import initial_frames
from kinecal.identification._lift import lifted_start
from kinecal.identification._lm import (
    LMOptions,
    LMResult,
    Prior,
    loss_weights,
    normal_equations,
    objective,
    solve_lm,
    spd_solve,
)
from kinecal.identification._measurements import Measurements
from kinecal.identification._metrics import Metrics, metrics_from_errors
from kinecal.identification._residuals import ResidualBlock, Weights, residuals
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = [
    "PRIOR_SIGMA",
    "CalibrationOptions",
    "CalibrationResult",
    "Outlier",
    "StageLog",
    "calibrate",
    "spec_for",
]

log = logging.getLogger(__name__)

_KINEMATIC_GROUPS = ("base", "joint", "cam")

# Prior standard deviations (SI) by parameter group and kind: physical scales of the
# deviations from nominal (DH), of transmission errors (NTM) and of per-unit-weight
# compliance and link moments; the mean is the start value (nominal, or zero).
PRIOR_SIGMA: dict[tuple[str, str], float] = {
    ("joint", "length"): 1e-3,  # 1 mm
    ("joint", "angle"): np.radians(0.1),  # 0.1 deg
    ("ntm", "ntm"): 5e-4,  # rad
    ("load", "compliance"): 1e-3,  # rad/m, i.e. 1e-5 rad/(N m) for a 10 kg payload
    ("link", "moment"): 2.0,  # m: link first moment per unit payload weight
    ("link", "ratio"): 10.0,  # link mass per payload mass
}
_PRIOR_GROUPS = {
    "none": (),
    "compliance": ("load", "link"),
    "all": ("joint", "ntm", "load", "link"),
}
# Median of the chi distribution with c degrees of freedom (norm of a c-D unit Gaussian).
_CHI_MEDIAN = {3: 1.5381722, 6: 2.3660319}
# Initial LM damping for a start next to the optimum (a lifted start, or the result of a
# fit with other weights or priors): Madsen, Nielsen & Tingleff, "Methods for non-linear
# least squares problems" (2004), Sec. 3.2, advise 1e-6 when the start is believed good
# and 1e-3 otherwise (LMOptions' default, used from nominal kinematics).
_MU0_WARM = 1e-6
# Stop an LM run once a step moves the estimate by about 1.4 % of its standard deviations
# (LMOptions.stol): further digits are far below the statistical uncertainty.
_STOL = 1e-4
# The unconstrained stage-1 pre-fit only gives the noise and the scale of the geometry
# priors before the real stage 1 starts from it: stopping at steps of sqrt(2 x 1e-2), about
# 14 % of a standard deviation, is close enough. On a robot with large joint compliances,
# which the kinematic model cannot fit, the pre-fit otherwise crawls for 100 iterations.
_STOL_PRE = 1e-2


@dataclass(frozen=True)
class CalibrationOptions:
    """Settings of :func:`calibrate`.

    Attributes
    ----------
    stage2 : {'direct', 'project', 'none'}
        How stage 2 fits the transmission terms: directly on the position residuals, by
        the paper's projection to joint space (Eq. 29), or not at all.
    loss : {'linear', 'huber', 'soft_l1'}
    f_scale_mm : float or None
        Where the robust loss bends (in mm of position error); default three times a
        robust estimate of the noise.
    max_iter : int
    drop_tol, weak_tol : float
        Identifiability tolerances (see :func:`analyse_identifiability`).
    outlier_p : float
        A row is reported as an outlier when its error is this unlikely under the fitted
        noise (chi distribution of the row's components).
    variance_components : bool
        Without per-row sigmas in the data, estimate the noise from the residuals (for pose
        data separately for position and orientation) and weight by it, so priors and data
        are balanced.
    priors : {'none', 'compliance', 'all'}
        Gaussian priors with physical scales (:data:`PRIOR_SIGMA`), making the estimate a
        maximum a posteriori one: 'all' (default) on the joint geometry, the transmission
        terms, the payload compliance and the link moments; 'compliance' on the payload
        and link-weight terms only (their product lambda* s is otherwise only weakly split);
        'none' is the paper's plain least squares.
    prior_sigma : dict, optional
        Per-parameter overrides ``{name: sigma (SI)}``; ``inf`` removes a prior.
    prior_scale : float
        Multiplies every prior sigma (``--model auto`` tries several).
    adapt_priors : bool
        Empirical Bayes. Widen the joint-geometry priors when an unconstrained kinematic
        fit shows larger deviations from nominal than they allow (method of moments on
        the well-determined parameters; never narrowed; reported in the warnings), and
        scale the transmission, payload and link-weight priors by maximum evidence
        (0.01x to 3x, ``CalibrationResult.prior_factors``), so terms the data do not
        support are shrunk instead of fitted to noise.
    """

    stage2: str = "direct"
    loss: str = "linear"
    f_scale_mm: float | None = None
    max_iter: int = 100
    drop_tol: float = 1e-6
    weak_tol: float = 1e-3
    outlier_p: float = 1e-5
    variance_components: bool = True
    priors: str = "all"
    prior_sigma: dict[str, float] | None = None
    prior_scale: float = 1.0
    adapt_priors: bool = True

    def __post_init__(self) -> None:
        if self.priors not in ("none", "compliance", "all"):
            raise ValueError(
                f"priors must be 'none', 'compliance' or 'all'; got {self.priors!r}."
            )
        if self.stage2 not in ("direct", "project", "none"):
            raise ValueError(
                f"stage2 must be 'direct', 'project' or 'none'; got {self.stage2!r}."
            )
        LMOptions(loss=self.loss)  # validates the loss name


@dataclass
class StageLog:
    """What one stage did."""

    name: str
    n_free: int
    rms_before_mm: float
    rms_after_mm: float
    iterations: int
    status: str
    success: bool
    seconds: float
    iteration_log: list[dict[str, float]] = field(default_factory=list)


@dataclass(frozen=True)
class Outlier:
    """A row whose error is improbable under the fitted noise."""

    row: int
    error_mm: float
    z: float


@dataclass
class CalibrationResult:
    """Everything :func:`calibrate` found.

    Attributes
    ----------
    calibrated : CalibratedModel, the identified model (what ``model.yaml`` stores).
    registered : (P,) parameters after registration only (nominal kinematics with fitted
        user and cam frames): the "before" state.
    covariance : (P, P) parameter covariance (zero rows for parameters not estimated).
    identifiability : Identifiability
    stages : list of StageLog
    metrics_before, metrics_after : Metrics on the calibration data.
    outliers : rows with improbable errors (never dropped silently).
    warnings : list of str
    success : bool, every stage converged.
    sigma0 : a-posteriori standard deviation of unit weight.
    prior_factors : scale applied to each group's default prior by maximum evidence
        (transmission 'ntm', payload 'load', link weight 'link'); empty if not tuned.
    """

    calibrated: CalibratedModel
    registered: Float
    covariance: Float
    identifiability: Identifiability
    stages: list[StageLog]
    metrics_before: Metrics
    metrics_after: Metrics
    outliers: list[Outlier]
    warnings: list[str]
    success: bool
    sigma0: float
    weights: Weights
    seconds: float
    prior: Prior | None = None
    prior_factors: dict[str, float] = field(default_factory=dict)

    @property
    def model(self) -> CalibrationModel:
        return self.calibrated.model

    @property
    def params(self) -> Float:
        return self.calibrated.params

    @property
    def std(self) -> Float:
        return self.calibrated.std

    def correlation(self) -> Float:
        from kinecal.identification._identifiability import correlation_from_covariance

        return correlation_from_covariance(self.covariance)


def spec_for(
    robot: RobotDescription,
    meas: Measurements,
    model: str | ModelSpec,
    **options: object,
) -> ModelSpec:
    """The model spec of a preset name (or a given spec) fitted to the data's structure.

    The data decides the user frames (one per set), the cam frames (one per marker) and
    whether the cam rotation is observable (not for position-only data).
    """
    cam_rotation = meas.kind != "point"
    if isinstance(model, ModelSpec):
        return replace(
            model,
            sets=meas.set_labels,
            markers=meas.marker_labels,
            cam_rotation=cam_rotation,
        )
    return ModelSpec.preset(
        model,
        cam_rotation=cam_rotation,
        sets=meas.set_labels,
        markers=meas.marker_labels,
        has_self_weight=robot.self_weight is not None,
        **options,  # type: ignore[arg-type]
    )


def _generic_point(model: CalibrationModel, x: Float) -> Float:
    """``x`` with compliance terms at generic values, for the structural rank.

    lambda* is non-zero (else the link moments would have no effect at all) but tiny:
    the analysis looks at the small-compliance limit, where parameters that differ only
    through second-order effects (lambda* times the change of a torque with the geometry,
    ~1e-4 of their effect) count as redundant, as they are in practice.
    """
    g = x.copy()
    for i, s in enumerate(model.layout.specs):
        if s.kind == "compliance":
            g[i] = 1e-7
        elif s.kind == "moment":
            g[i] = 0.3 + 0.1 * (i % 3)
        elif s.kind == "ratio":
            g[i] = 1.0
    return g


def build_prior(
    model: CalibrationModel, start: Float, options: CalibrationOptions
) -> Prior:
    """Priors of :data:`PRIOR_SIGMA` (or the robot file's ``priors``) for the groups
    chosen in ``options.priors``; ``options.prior_sigma`` overrides single parameters."""
    sigma = np.full(model.size, np.inf)
    groups = _PRIOR_GROUPS[options.priors]
    table = {**PRIOR_SIGMA, **model.robot.prior_sigma}  # the robot file may override
    for i, s in enumerate(model.layout.specs):
        if s.group in groups:
            sigma[i] = table.get((s.group, s.kind), np.inf) * options.prior_scale
    for name, value in (options.prior_sigma or {}).items():
        sigma[model.layout.index(name)] = float(value)
    return Prior(start.copy(), sigma)


class _Evaluations:
    """Residual blocks of one calibration: each point is evaluated once.

    The identification revisits points (a stage starts where the last one ended, the
    priors, stage 2 and the uncertainty look at a stage's solution, the log reports the
    error before and after each stage). The last few blocks are kept, keyed by the model,
    the parameters and the weights; raw position errors do not depend on the weights.
    Each block also keeps the model's forward state, so the Jacobian at a point evaluated
    before (the LM's accepted trial point, typically) skips the forward kinematics.
    """

    def __init__(self, meas: Measurements, inputs: ModelInputs, keep: int = 3) -> None:
        self.meas = meas
        self.inputs = inputs
        self._keep = keep
        self._blocks: list[tuple[CalibrationModel, bytes, Weights, ResidualBlock]] = []

    def __call__(
        self,
        cm: CalibrationModel,
        x: Float,
        w: Weights,
        *,
        jacobian: bool = False,
        products: bool = False,
    ) -> ResidualBlock:
        """The residual block at ``x`` (see :func:`residuals`)."""
        key = np.asarray(x, np.float64).tobytes()
        n_cols = cm.size + (len(cm.link_products) if products else 0)
        forward = None  # the model's forward state at x, from any block (any weights)
        for m, k, ww, blk in reversed(self._blocks):
            if m is cm and k == key:
                if ww is w and (
                    not jacobian or (blk.J is not None and blk.J.shape[-1] >= n_cols)
                ):
                    return blk
                forward = forward or blk.forward
        blk = residuals(
            cm,
            x,
            self.meas,
            w,
            inputs=self.inputs,
            jacobian=jacobian,
            products=products,
            keep=True,
            reuse=forward,
        )
        self._blocks = [*self._blocks[-(self._keep - 1) :], (cm, key, w, blk)]
        return blk

    def raw_position(self, cm: CalibrationModel, x: Float, w: Weights) -> Float:
        """Position errors (N, 3) at ``x`` [m], from any block kept at that point."""
        key = np.asarray(x, np.float64).tobytes()
        for m, k, _, blk in reversed(self._blocks):
            if m is cm and k == key:
                return blk.raw_position
        return self(cm, x, w).raw_position


def _drift(cm: CalibrationModel, res: LMResult, free: np.ndarray, priors: str) -> str:
    """Where a run that hit its iteration limit was still going: the parameters that
    dominate the remaining Gauss-Newton step (in characteristic units), with their
    values. Such a run crawls down a long valley, typically a term the poses hardly
    determine (a joint compliance whose torque stays small at every pose, say)."""
    if res.status != "max_iter" or res.gradient.size == 0:
        return ""
    dz = -spd_solve(res.normal_matrix, res.gradient, rcond=1e-14)
    size = np.abs(dz)
    if not np.isfinite(size).all() or size.max() == 0.0:
        return ""
    fidx = np.flatnonzero(free)
    lead = [k for k in np.argsort(-size)[:3] if size[k] >= 0.3 * size.max()]
    parts = []
    for k in lead:
        spec = cm.layout.specs[fidx[k]]
        unit = spec.unit
        parts.append(
            f"{spec.name} (now {res.x[fidx[k]] * unit.to_file:.4g} {unit.file_unit})"
        )
    text = "; the estimate still drifts along " + ", ".join(parts)
    text += ", which these poses hardly determine"
    if priors != "all":
        text += " (the default priors, --priors all, hold such terms)"
    return text


def _loose_parameters(
    cm: CalibrationModel,
    start: Float,
    opts: CalibrationOptions,
    sigma: Float,
    std: Float,
    fidx: np.ndarray,
) -> list[tuple[str, float]]:
    """Estimated parameters without a prior (``sigma`` infinite) whose standard
    deviation exceeds the prior ``--priors all`` would give them (their plausible size),
    as ``(name, std / that prior)``, largest first: plain least squares leaves them to
    the noise."""
    plausible = build_prior(cm, start, replace(opts, priors="all")).sigma
    out = [
        (cm.layout.names[i], float(std[i] / plausible[i]))
        for i in fidx
        if not np.isfinite(sigma[i])
        and np.isfinite(plausible[i])
        and std[i] > plausible[i]
    ]
    return sorted(out, key=lambda item: -item[1])


def _robust_sigma(r: Float) -> float:
    """Noise per component from the median row norm (whitened units)."""
    c = r.shape[1]
    med = median(np.linalg.norm(r, axis=1))
    return med / _CHI_MEDIAN.get(c, np.sqrt(c - 0.5))


def calibrate(
    robot: RobotDescription,
    meas: Measurements,
    model: str | ModelSpec = "full",
    options: CalibrationOptions | None = None,
    *,
    progress: object | None = None,
) -> CalibrationResult:
    """Identify a model from measurements, starting from nominal kinematics alone.

    Parameters
    ----------
    robot : RobotDescription
    meas : Measurements
    model : preset name ('kinematic', 'ntm', 'rfcm', 'full') or a ModelSpec
    options : CalibrationOptions
    progress : callable ``progress(stage: str, detail: str)``, optional

    Returns
    -------
    CalibrationResult
        Non-convergence is reported in ``success`` and ``warnings``, not raised.

    Raises
    ------
    DataError
        The data does not fit the robot (joint count).
    IdentifiabilityError
        Too few poses for the model.
    """
    t_start = time.perf_counter()
    opts = options or CalibrationOptions()
    say = progress if callable(progress) else (lambda stage, detail: None)
    if meas.n_joints != robot.n_joints:
        raise DataError(
            f"{meas.source} has {meas.n_joints} joint columns; robot {robot.name} has "
            f"{robot.n_joints} joints."
        )
    spec = spec_for(robot, meas, model)
    cm = CalibrationModel(robot, spec)
    c = meas.components
    m_res = meas.n * c
    if m_res <= cm.size:
        need = cm.size // c + 1
        raise IdentifiabilityError(
            f"{meas.source}: {meas.n} poses give {m_res} residuals, but the '{spec.name}' "
            f"model has {cm.size} parameters; measure at least {need} poses "
            f"(several times more for a reliable result)."
        )
    warnings: list[str] = []
    ref_payload = meas.reference_payload() or robot.payload_kg
    inputs: ModelInputs = meas.model_inputs(ref_payload)
    weights = Weights.default(meas)
    lm_linear = LMOptions(max_iter=opts.max_iter, stol=_STOL)

    ev = _Evaluations(meas, inputs)

    def make_fun(model_: CalibrationModel, w: Weights, products: bool):
        def fun(x: Float, jac: bool) -> tuple[Float, Float | None]:
            blk = ev(model_, x, w, jacobian=jac, products=products)
            return blk.r, blk.J

        return fun

    def rms_mm(model_: CalibrationModel, x: Float) -> float:
        e_p = ev.raw_position(model_, x, weights)
        return float(np.sqrt(np.mean(np.sum(e_p**2, axis=1)))) * 1e3

    # ---------------------------------------------------------------- registration
    say("init", "closed-form user and cam frames")
    cm, x = initial_frames(cm, cm.nominal.copy(), meas)
    groups = np.array([s.group for s in cm.layout.specs])
    frames = np.isin(groups, ("base", "cam"))
    kin = np.isin(groups, _KINEMATIC_GROUPS)
    stages: list[StageLog] = []

    def lift(
        x0: Float, free: np.ndarray, lm: LMOptions, w: Weights, prior: Prior | None
    ) -> Float:
        """The lifted start (:mod:`._lift`), kept where it does not raise the cost."""
        if not any(free[a] and free[b] for a, b in cm.link_products):
            return x0
        blk = ev(cm, x0, w, jacobian=True, products=True)
        assert blk.J is not None
        cost0, drho = objective(blk.r, lm)
        sw = None if lm.loss == "linear" else np.sqrt(drho)
        x1 = lifted_start(cm, x0, blk.r, blk.J, free, prior, sw)
        # With the Jacobian the stage's LM starts with (served from the cache then).
        cost1 = objective(ev(cm, x1, w, jacobian=True, products=True).r, lm)[0]
        if prior is not None:
            cost0, cost1 = cost0 + prior.cost(x0), cost1 + prior.cost(x1)
        return x1 if cost1 <= cost0 else x0

    def run(
        name: str,
        x0: Float,
        free: np.ndarray,
        lm: LMOptions,
        w: Weights,
        prior: Prior | None = None,
        required: bool = True,
        lifted: bool = False,
    ) -> LMResult:
        before = rms_mm(cm, x0)
        say(name, f"{int(free.sum())} parameters")
        t0 = time.perf_counter()
        if lifted:
            x0 = lift(x0, free, lm, w, prior)
            lm = replace(lm, mu0=_MU0_WARM)
        res = solve_lm(  # a lifted stage's Jacobians carry the product columns
            make_fun(cm, w, lifted),
            x0,
            free,
            cm.layout.scales,
            lm,
            prior=prior,
            label=name,
        )
        after = rms_mm(cm, res.x)
        stages.append(
            StageLog(
                name,
                int(free.sum()),
                before,
                after,
                res.n_iter,
                res.status,
                res.success,
                time.perf_counter() - t0,
                res.log,
            )
        )
        log.info(
            "%s: rms %.4f -> %.4f mm (%s, %d it)",
            name,
            before,
            after,
            res.status,
            res.n_iter,
        )
        if not res.success and required:
            warnings.append(
                f"{name} did not converge: {res.message}"
                + _drift(cm, res, free, opts.priors)
                + "."
            )
        stages[-1].success = res.success or not required
        return res

    reg = run("registration", x, frames, lm_linear, weights)
    x_reg = reg.x
    if meas.kind == "pose" and opts.variance_components and meas.sigma is None:
        weights = _noise_from_residuals(cm, x_reg, ev, weights, int(frames.sum()))
        x_reg = run("registration", x_reg, frames, lm_linear, weights).x

    # ---------------------------------------------------------------- identifiability
    say("identifiability", "scaled Jacobian")
    blk = residuals(
        cm, _generic_point(cm, x_reg), meas, weights, inputs=inputs, jacobian=True
    )
    assert blk.J is not None
    ident = analyse_identifiability(
        blk.J.transpose(2, 1, 0).reshape(cm.size, -1).T,  # (m, P), no copy
        cm.layout,
        np.ones(cm.size, bool),
        drop_tol=opts.drop_tol,
        weak_tol=opts.weak_tol,
    )
    free = ident.free
    if meas.kind == "sensor" and meas.targets is not None:
        assert meas.target_index is not None
        for si, label in enumerate(meas.set_labels):
            seen = np.unique(meas.target_index[meas.set_index == si])
            pts = meas.targets[seen]
            spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
            if seen.size < 3 or spread[1] < 1e-3 * max(spread[0], 1e-12):
                warnings.append(
                    f"set {label or '(default)'} sees {seen.size} target(s)"
                    + (" on one line" if seen.size >= 3 else "")
                    + ": the rotation of its user frame about the line through them is "
                    "not determined, so predictions at other targets are unreliable. "
                    "Measure at least three targets not on one line."
                )
    frames_lost = [
        d.name for d in ident.dropped if d.name.split(".", 1)[0] in ("base", "cam")
    ]
    if frames_lost:
        warnings.append(
            f"the poses do not determine {', '.join(frames_lost)}: the user frame and "
            "the tool offset trade off (too little variation of the tool orientation). "
            "They are kept at their starting values; predictions at orientations unlike "
            "the calibration poses can be far off. Measure with varied orientations."
        )
    if m_res <= free.sum():
        raise IdentifiabilityError(
            f"{meas.source}: {meas.n} poses ({m_res} residuals) cannot determine "
            f"{int(free.sum())} parameters."
        )

    # ---------------------------------------------------------------- stage 1
    prior = build_prior(cm, x_reg, opts)
    prior_kin = Prior(prior.mean, np.where(kin, prior.sigma, np.inf))
    use_prior_kin = bool(np.any(np.isfinite(prior_kin.sigma) & free & kin))
    estimate_noise = opts.variance_components and meas.sigma is None
    # The first stage-1 fit has no priors. Its residuals give the noise (when the data
    # carry no sigmas): a prior weighed against the registration residuals (the nominal
    # model's error, far above the noise) would hold the fit back, inflate the noise
    # estimate and so keep the prior too strong, a self-confirming misfit seen on real
    # mocap data. Its deviations from nominal give the scale of the joint-geometry
    # priors (empirical Bayes, see _adapt_prior).
    needed = use_prior_kin or (estimate_noise and meas.kind == "pose")
    pre = run(
        "stage 1: kinematic" + (" (no priors)" if use_prior_kin else ""),
        x_reg,
        free & kin,
        replace(lm_linear, stol=_STOL_PRE) if needed else lm_linear,
        weights,
        required=not needed,
    )
    x1 = pre.x
    if estimate_noise:
        weights = _noise_from_residuals(cm, x1, ev, weights, int((free & kin).sum()))
    if use_prior_kin and opts.adapt_priors and pre.success:
        prior, widened = _adapt_prior(cm, x1, x_reg, prior, ev, weights, free & kin)
        prior_kin = Prior(prior.mean, np.where(kin, prior.sigma, np.inf))
        if widened:
            warnings.append(
                "the data show larger deviations from nominal than the default priors "
                "allow; priors widened: "
                + ", ".join(f"{what} {value}" for what, value in widened)
                + "."
            )
    if needed:
        x1 = run(
            "stage 1: kinematic",
            x1,
            free & kin,
            lm_linear,
            weights,
            prior_kin if use_prior_kin else None,
        ).x
    lm = lm_linear
    if opts.loss != "linear":
        r1 = ev(cm, x1, weights).r
        if opts.f_scale_mm is not None:
            f_scale = opts.f_scale_mm * 1e-3 / median(weights.sigma)
        else:
            f_scale = 3.0 * _robust_sigma(r1) * np.sqrt(c)
        lm = LMOptions(
            max_iter=opts.max_iter, loss=opts.loss, f_scale=f_scale, stol=_STOL
        )
        x1 = run(
            "stage 1: kinematic (robust)",
            x1,
            free & kin,
            lm,
            weights,
            prior_kin if use_prior_kin else None,
        ).x

    # ---------------------------------------------------------------- stage 2
    x2 = x1
    ntm = groups == "ntm"
    if np.any(ntm & free) and opts.stage2 != "none":
        before = rms_mm(cm, x1)
        t0 = time.perf_counter()
        say("stage 2: transmission", opts.stage2)
        x2 = (_stage2_project if opts.stage2 == "project" else _stage2_direct)(
            cm, x1, ev, weights, free & ntm
        )
        after = rms_mm(cm, x2)
        if after > before:  # a linear fit cannot be trusted to help: keep stage 1
            x2 = x1
            after = before
        stages.append(
            StageLog(
                f"stage 2: transmission ({opts.stage2})",
                int((free & ntm).sum()),
                before,
                after,
                1,
                "linear",
                True,
                time.perf_counter() - t0,
            )
        )

    # ---------------------------------------------------------------- stage 3
    prior_factors: dict[str, float] = {}
    x_final = x1
    use_prior = bool(np.any(np.isfinite(prior.sigma) & free))
    if np.any(free & ~kin):
        lm3 = replace(lm, max_iter=max(lm.max_iter, 200))
        x_final = run(
            "stage 3: all",
            x2,
            free,
            lm3,
            weights,
            prior if use_prior else None,
            lifted=True,
        ).x
        if estimate_noise:
            w3 = _noise_from_residuals(cm, x_final, ev, weights, int(free.sum()))
            if abs(np.log(w3.sigma[0] / weights.sigma[0])) > np.log(1.2):
                weights = w3  # priors were weighed against too high a noise: once more
                x_final = run(
                    "stage 3: all",
                    x_final,
                    free,
                    lm3,
                    weights,
                    prior if use_prior else None,
                    lifted=True,
                ).x

        if use_prior and opts.adapt_priors:
            prior, chosen = _evidence_prior(cm, x_final, ev, weights, free, prior, lm3)
            if any(f != 1.0 for f in chosen.values()):
                log.info("prior scales from the evidence: %s", chosen)
                x_final = run(
                    "stage 3: all (evidence priors)",
                    x_final,
                    free,
                    lm3,
                    weights,
                    prior,
                    lifted=True,
                ).x
            prior_factors = chosen

    # ---------------------------------------------------------------- uncertainty
    fidx = np.flatnonzero(free)
    scales = cm.layout.scales[fidx]
    r_final = ev(cm, x_final, weights, jacobian=True)
    assert r_final.J is not None
    wr = loss_weights(np.sum(r_final.r**2, axis=1) / lm.f_scale**2, lm.loss)[1]
    dof = m_res - fidx.size
    sigma0 = float(np.sqrt(np.sum(wr[:, None] * r_final.r**2) / max(dof, 1)))
    A, _ = normal_equations(
        r_final.r, r_final.J, fidx, scales, None if lm.loss == "linear" else np.sqrt(wr)
    )
    if use_prior:
        A = A + np.diag(prior.precision[fidx] * scales**2)
    cov = np.zeros((cm.size, cm.size))
    try:
        cov_f = sigma0**2 * _psd_inverse(A, 1e-14) * np.outer(scales, scales)
        cov[np.ix_(fidx, fidx)] = cov_f
    except np.linalg.LinAlgError:
        warnings.append(
            "the normal matrix could not be inverted; no standard deviations."
        )
    std = np.full(cm.size, np.nan)
    std[fidx] = np.sqrt(np.clip(np.diag(cov)[fidx], 0.0, None))
    status = ["estimated" if f else "unidentifiable" for f in free]

    # ---------------------------------------------------------------- report
    e_before = ev(cm, x_reg, weights)
    metrics_before = metrics_from_errors(e_before.raw_position, e_before.raw_rotation)
    metrics_after = metrics_from_errors(r_final.raw_position, r_final.raw_rotation)
    outliers = _outliers(r_final.r, r_final.raw_position, meas, opts.outlier_p)
    if outliers:
        what = "down-weighted" if opts.loss != "linear" else "kept (use --loss huber)"
        warnings.append(
            f"{len(outliers)} rows look like outliers; {what}: rows "
            + ", ".join(str(o.row) for o in outliers[:10])
            + (" ..." if len(outliers) > 10 else "")
            + "."
        )
    if use_prior:
        # Terms the data barely inform: the posterior is (almost) the prior.
        weak_prior = [
            cm.layout.names[i]
            for i in fidx
            if np.isfinite(prior.sigma[i]) and std[i] > 0.7 * prior.sigma[i]
        ]
        if weak_prior:
            warnings.append(
                f"{len(weak_prior)} parameters are determined mostly by their prior, not by "
                f"the data: {', '.join(weak_prior[:8])}"
                + (" ..." if len(weak_prior) > 8 else "")
                + "."
            )
    loose = _loose_parameters(cm, x_reg, opts, prior.sigma, std, fidx)
    if loose:
        warnings.append(
            f"{len(loose)} parameters without a prior are hardly determined by these "
            "poses: their standard deviation exceeds the size the default priors allow "
            "(--priors all): "
            + ", ".join(f"{name} ({ratio:.3g}x)" for name, ratio in loose[:8])
            + (f" and {len(loose) - 8} more" if len(loose) > 8 else "")
            + "."
        )
    ratio = fidx.size / m_res
    if ratio > 0.2:
        warnings.append(
            f"{fidx.size} parameters from {m_res} residuals ({ratio:.0%}): results may "
            "overfit; validate on other poses."
        )
    for d in ident.dropped:
        log.info("unidentifiable: %s", d.describe())
    success = all(s.success for s in stages)
    calibrated = CalibratedModel(
        cm,
        x_final,
        std,
        status,
        ref_payload,
        info={
            "source": meas.source,
            "kind": meas.kind,
            "n": meas.n,
            "model": spec.name,
        },
    )
    return CalibrationResult(
        calibrated=calibrated,
        registered=x_reg,
        covariance=cov,
        identifiability=ident,
        stages=stages,
        metrics_before=metrics_before,
        metrics_after=metrics_after,
        outliers=outliers,
        warnings=warnings,
        success=success,
        sigma0=sigma0,
        weights=weights,
        seconds=time.perf_counter() - t_start,
        prior=prior if use_prior else None,
        prior_factors=prior_factors,
    )


def _psd_inverse(A: Float, rcond: float) -> Float:
    """Pseudo-inverse of a symmetric positive semi-definite matrix, eigenvalues below
    ``rcond`` times the largest left out."""
    evals, evecs = np.linalg.eigh(A)
    good = evals > evals.max() * rcond
    return (evecs[:, good] / evals[good]) @ evecs[:, good].T


def _adapt_prior(
    cm: CalibrationModel,
    x: Float,
    x_nominal: Float,
    prior: Prior,
    ev: _Evaluations,
    w: Weights,
    free: np.ndarray,
) -> tuple[Prior, list[tuple[str, str]]]:
    """Joint-geometry prior scales from an unconstrained fit (empirical Bayes).

    For each kind (lengths, angles) the prior variance is estimated by the method of
    moments, ``tau^2 = mean(dx^2 - var(dx))`` over the free parameters of that kind with a
    finite prior, ``dx`` the deviation from nominal and ``var`` its variance from the
    unconstrained fit. The prior sigma becomes ``max(sigma, tau)``: a robot whose geometry
    departs from its nominal table by more than the default prior allows is not pulled
    back, while a poorly determined parameter (large ``var``) does not widen it.
    """
    fidx = np.flatnonzero(free)
    blk = ev(cm, x, w, jacobian=True)
    assert blk.J is not None
    scales = cm.layout.scales[fidx]
    JtJ, _ = normal_equations(blk.r, blk.J, fidx, scales)
    dof = max(blk.r.size - fidx.size, 1)
    s0sq = float(np.sum(blk.r**2)) / dof
    var = s0sq * np.diag(_psd_inverse(JtJ, 1e-12)) * scales**2
    sigma = prior.sigma.copy()
    widened: list[tuple[str, str]] = []
    kinds = np.array([cm.layout.specs[i].kind for i in fidx])
    groups = np.array([cm.layout.specs[i].group for i in fidx])
    for kind, unit, factor in (("length", "mm", 1e3), ("angle", "deg", np.degrees(1))):
        sel = (groups == "joint") & (kinds == kind) & np.isfinite(sigma[fidx])
        if not sel.any():
            continue
        idx = fidx[sel]
        dx = x[idx] - x_nominal[idx]
        tau2 = float(np.mean(dx**2 - var[sel]))
        current = median(sigma[idx])
        if tau2 > current**2:
            tau = float(np.sqrt(tau2))
            sigma[idx] = np.maximum(sigma[idx], tau)
            widened.append((f"joint {kind}s", f"{tau * factor:.3g} {unit}"))
        # A deviation the data determine clearly (beyond 3 of its own std) and beyond
        # its prior is not pulled back: its prior widens to the deviation itself.
        clear = (np.abs(dx) > 3.0 * np.sqrt(var[sel])) & (np.abs(dx) > sigma[idx])
        for i, d in zip(idx[clear], dx[clear]):
            sigma[i] = abs(d)
            widened.append((cm.layout.names[i], f"{abs(d) * factor:.3g} {unit}"))
    return Prior(prior.mean, sigma), widened


_EVIDENCE_GROUPS = ("ntm", "load", "link")
_EVIDENCE_FACTORS = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0)


def _evidence_prior(
    cm: CalibrationModel,
    x: Float,
    ev: _Evaluations,
    w: Weights,
    free: np.ndarray,
    prior: Prior,
    lm: LMOptions,
) -> tuple[Prior, dict[str, float]]:
    """Prior scales of the transmission and compliance groups by maximum evidence.

    With the model linearised at ``x`` (whitened residuals ``r``, Jacobian ``J``) and
    the prior ``N(m, S)``, the data are Gaussian with covariance ``I + J S Jᵀ`` about the
    prediction at ``m``; its log density (the evidence) is evaluated through Woodbury's
    identity for each candidate scale of a group's sigmas, by coordinate ascent over the
    groups. A group the data do not support gets a smaller prior (it is shrunk towards
    zero), one they do support keeps or widens it (at most 3x). Parameters without a prior
    enter with a very wide one, the same for every candidate, so they do not bias the
    comparison. With a robust loss the rows carry their IRLS weights at ``x``.
    """
    fidx = np.flatnonzero(free)
    groups = np.array([cm.layout.specs[i].group for i in fidx])
    tune = [
        g
        for g in _EVIDENCE_GROUPS
        if np.any((groups == g) & np.isfinite(prior.sigma[fidx]))
    ]
    if not tune:
        return prior, {}
    blk = ev(cm, x, w, jacobian=True)
    assert blk.J is not None
    sc = cm.layout.scales[fidx]
    sw = np.sqrt(loss_weights(np.sum(blk.r**2, axis=1) / lm.f_scale**2, lm.loss)[1])
    JtJ, Jtr = normal_equations(blk.r, blk.J, fidx, sc, sw)
    # b = r + J (m - x): the data about the prediction at the prior mean
    d = (prior.mean[fidx] - x[fidx]) / sc
    Jtb = Jtr + JtJ @ d
    btb = float(np.sum((blk.r * sw[:, None]) ** 2) + 2.0 * (Jtr @ d) + d @ JtJ @ d)
    base_var = np.where(
        np.isfinite(prior.sigma[fidx]), (prior.sigma[fidx] / sc) ** 2, 1e8
    )

    def log_evidence(var: Float) -> float:
        M = JtJ + np.diag(1.0 / var)
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return -np.inf
        y = np.linalg.solve(L, Jtb)
        quad = btb - float(y @ y)
        logdet = float(np.sum(np.log(var))) + 2.0 * float(np.sum(np.log(np.diag(L))))
        return -0.5 * (quad + logdet)

    factors = {g: 1.0 for g in tune}

    def variance() -> Float:
        v = base_var.copy()
        for g, f in factors.items():
            v[groups == g] *= f * f
        return v

    for _ in range(2):  # coordinate ascent
        for g in tune:
            best = (log_evidence(variance()), factors[g])
            for f in _EVIDENCE_FACTORS:
                factors[g] = f
                le = log_evidence(variance())
                if le > best[0] + 1e-9:
                    best = (le, f)
            factors[g] = best[1]
    sigma = prior.sigma.copy()
    for g, f in factors.items():
        sel = np.array([s.group == g for s in cm.layout.specs]) & np.isfinite(sigma)
        sigma[sel] *= f
    return Prior(prior.mean, sigma), factors


def _noise_from_residuals(
    cm: CalibrationModel,
    x: Float,
    ev: _Evaluations,
    w: Weights,
    n_free: int,
) -> Weights:
    """Noise per component from the residuals, corrected for the parameters fitted.

    Pose data get separate position and orientation sigmas (variance components).
    """
    blk = ev(cm, x, w)
    m = blk.r.size
    n = ev.meas.n
    dof_scale = np.sqrt(m / max(m - n_free, 1))
    s_p = float(np.sqrt(np.mean(blk.raw_position**2))) * dof_scale
    if blk.raw_rotation is None:
        return Weights(np.full(n, max(s_p, 1e-12)))
    s_r = float(np.sqrt(np.mean(blk.raw_rotation**2))) * dof_scale
    return Weights(np.full(n, max(s_p, 1e-12)), np.full(n, max(s_r, 1e-12)))


def _stage2_direct(
    cm: CalibrationModel,
    x: Float,
    ev: _Evaluations,
    w: Weights,
    cols: np.ndarray,
) -> Float:
    """Fourier coefficients by linear least squares on the whitened residuals."""
    blk = ev(cm, x, w, jacobian=True)
    assert blk.J is not None
    idx = np.flatnonzero(cols)
    A = blk.J[:, :, idx].reshape(-1, idx.size)
    delta, *_ = np.linalg.lstsq(A, -blk.r.reshape(-1), rcond=None)
    out = x.copy()
    out[idx] += delta
    return out


def _stage2_project(
    cm: CalibrationModel,
    x: Float,
    ev: _Evaluations,
    w: Weights,
    cols: np.ndarray,
) -> Float:
    """The paper's stage 2: residuals to joint space by Eq. (29), then Fourier LS per joint."""
    from kinecal.models import ntm_basis

    spec = cm.spec
    joints = list(spec.ntm_joints)
    meas = ev.meas
    blk = ev(cm, x, w)
    Jq = cm.joint_jacobian(x, ev.inputs)[:, :3, :]  # (N, 3, n) position part
    Jt = Jq[:, :, [j - 1 for j in joints]]
    e = -blk.raw_position  # joint errors that would remove the residual
    if len(joints) == 3:
        dth = np.linalg.solve(Jt, e[:, :, None])[:, :, 0]  # Eq. (29), per point 3x3
    else:
        dth = (np.linalg.pinv(Jt) @ e[:, :, None])[:, :, 0]
    out = x.copy()
    names = cm.layout.names
    for k, j in enumerate(joints):
        idx = np.array(
            [i for i in np.flatnonzero(cols) if names[i].startswith(f"joint{j}.")]
        )
        if idx.size == 0:
            continue
        B = ntm_basis(meas.q_ctrl[:, j - 1], spec.ntm_order, spec.ntm_offset)
        col_names = [n.split(".", 1)[1] for n in np.array(names)[idx]]
        all_cols = (["k0"] if spec.ntm_offset else []) + [
            f"k{ab}{h}" for h in range(1, spec.ntm_order + 1) for ab in "ab"
        ]
        Bsel = B[:, [all_cols.index(cn) for cn in col_names]]
        coef, *_ = np.linalg.lstsq(Bsel, dth[:, k], rcond=None)
        out[idx] += coef
    return out


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


def _outliers(r: Float, e_pos: Float, meas: Measurements, p: float) -> list[Outlier]:
    c = r.shape[1]
    sigma = _robust_sigma(r)
    if sigma <= 0:
        return []
    z = np.linalg.norm(r, axis=1) / sigma
    thr = math.sqrt(chi2_isf(c, p))  # chi-square quantile: P(X > thr^2) = p
    bad = np.flatnonzero(z > thr)
    err = np.linalg.norm(e_pos, axis=1) * 1e3
    order = bad[np.argsort(-z[bad])]
    return [Outlier(int(meas.rows[i]), float(err[i]), float(z[i])) for i in order]
