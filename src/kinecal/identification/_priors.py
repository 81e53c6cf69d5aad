"""Priors: physical scales, adapted to the data by empirical Bayes (theory.md §4).

:class:`Priors` sets Gaussian priors (:data:`PRIOR_SIGMA`, Eq. (T-6)) and widens the
joint-geometry ones where an unconstrained stage-1 fit shows larger deviations from nominal
(method of moments, Eq. (T-8)). :class:`EvidencePriors` scales the transmission,
compliance and joint-geometry priors by maximum evidence (Eq. (T-9)) and fits again with
them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal._log import Logger
from kinecal._record import Record
from kinecal._stats import median
from kinecal.identification._lm import Prior, loss_weights, psd_inverse
from kinecal.identification._noise import estimate_noise
from kinecal.identification._normal import block_normal
from kinecal.identification._options import (
    PRIOR_GROUPS,
    PRIOR_SIGMA,
    STOL_PRE,
    CalibrationOptions,
    PriorSettings,
)
from kinecal.identification._problem import Problem, State
from kinecal.identification._solve import SolverRun, run_lm
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.models import CalibrationModel, ParamSpec
from kinecal.typing import Float

__all__ = ["EvidencePriors", "Priors", "build_prior", "evidence_group"]

log = Logger(__name__)

_EVIDENCE_GROUPS = ("ntm", "load", "link", "joint:length", "joint:angle")
_EVIDENCE_FACTORS = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0)
# The joint geometry: its prior may narrow to a tenth (or widen 3x) where the data say so.
_GEOMETRY_FACTORS = (0.1, 0.3, 1.0, 3.0)
# The link priors of a robot with link masses are at least this fraction of the file's
# values (a URDF's CAD inertials are rarely closer).
LINK_REL = 0.2


def build_prior(
    model: CalibrationModel,
    start: Float,
    options: CalibrationOptions | PriorSettings,
) -> Prior:
    """Priors of :data:`PRIOR_SIGMA` (or the robot file's ``priors``; the joint
    compliances of a robot with link masses: :func:`kinecal.robot.compliance_priors`)
    for the groups chosen in ``options.priors``, centred on ``start``, times the prior
    scale; the per-parameter ``prior_sigma`` overrides single parameters (Eq. (T-6))."""
    from kinecal.robot import compliance_priors

    if isinstance(options, CalibrationOptions):
        options = PriorSettings.of(options)
    sigma = np.full(model.size, np.inf)
    groups = PRIOR_GROUPS[options.priors]
    table = {**PRIOR_SIGMA, **model.robot.prior_sigma}  # the robot file may override
    lam = compliance_priors(model.robot)  # per joint, from the link masses
    floor = _link_floor(model)
    for i, s in enumerate(model.layout.specs):
        if s.group in groups:
            sd = table.get((s.group, s.kind), np.inf)
            if (s.group, s.kind) == ("load", "compliance"):
                sd = lam.get(s.joint or 0, sd)
            if s.group == "link" and (s.group, s.kind) not in model.robot.prior_sigma:
                sd = max(sd, floor[i])
            sigma[i] = sd * options.prior_scale
    for name, value in (options.prior_sigma or {}).items():
        sigma[model.layout.index(name)] = float(value)
    return Prior(start.copy(), sigma)


def _link_floor(model: CalibrationModel) -> Float:
    """The least prior std of each general link term: :data:`LINK_REL` of the file's
    value (a body's mass per reference payload mass, a component of its first moment
    per reference payload weight); 0 elsewhere. A 1000 kg link of a 1 kg reference
    payload (ratio 1000) is known to some 100 kg, not to the table's 10 (Eq. (T-6b))."""
    link = [s.group == "link" and s.joint is not None for s in model.layout.specs]
    return np.where(link, LINK_REL * np.abs(model.nominal), 0.0)


@dataclass(frozen=True, eq=False, repr=False)
class Priors(Record):
    """Set the priors, centred on the registered parameters.

    When the joint geometry has priors (or pose data need their noise), a first stage-1
    fit without priors runs: its residuals give the noise (a prior weighed against the
    registration residuals, the nominal model's error far above the noise, would hold the
    fit back, inflate the noise estimate and so keep the prior too strong: a
    self-confirming misfit seen on real mocap data), and its deviations from nominal the
    scale of the joint-geometry priors (:func:`adapt_prior`; ``priors_widened``).
    """

    name: str = "priors"
    settings: PriorSettings | None = None  # None: from the problem's options

    def __call__(self, problem: Problem, state: State) -> State:
        kin = problem.kinematic
        opts = self.settings or PriorSettings.of(problem.options)
        prior = build_prior(state.model, state.x, opts)
        state = state.but(prior=prior)
        use_prior_kin = state.active_prior(kin) is not None
        needed = use_prior_kin or (
            problem.estimate_noise and problem.meas.kind == "pose"
        )
        if not needed:
            return state
        x_reg = state.x
        name = "stage 1: kinematic" + (" (no priors)" if use_prior_kin else "")
        lm_pre = replace(state.lm, stol=STOL_PRE)
        state, pre = run_lm(
            problem,
            state,
            name,
            x_reg,
            state.free & kin,
            lm_pre,
            required=False,
            products=bool(state.model.link_products),  # stage 3 lifts from there
        )
        # Stage 1 without priors from the identified state (the rejection's probe, the
        # nominal check) continues this run instead of repeating it.
        ident = state.identified
        run = SolverRun.of(problem, state, x_reg, state.free & kin, lm_pre, pre)
        if ident is not None and run is not None:
            state = state.but(identified=ident.but(prefit=run))
        state = state.but(x=pre.x)
        if problem.estimate_noise:
            state = estimate_noise(problem, state, pre.x, state.free & kin, None)
        if use_prior_kin and opts.adapt_priors and pre.success:
            prior, widened = adapt_prior(problem, state, pre.x, x_reg, prior)
            state = state.but(prior=prior)
            if widened:
                state = state.note(
                    Diagnostic(
                        "priors_widened",
                        "the data show larger deviations from nominal than the default "
                        "priors allow; priors widened: "
                        + ", ".join(f"{what} {value}" for what, value in widened)
                        + ".",
                        parameters=tuple(
                            w for w, _ in widened if w in state.model.layout
                        ),
                        stage=self.name,
                    )
                )
        return state


def adapt_prior(
    problem: Problem, state: State, x: Float, x_nominal: Float, prior: Prior
) -> tuple[Prior, list[tuple[str, str]]]:
    """Joint-geometry prior scales from an unconstrained fit (empirical Bayes).

    For each kind (lengths, angles) the prior variance is estimated by the method of
    moments, ``tau^2 = mean(dx^2 - var(dx))`` over the free parameters of that kind with a
    finite prior, ``dx`` the deviation from nominal and ``var`` its variance from the
    unconstrained fit (Eq. (T-8)). The prior sigma becomes ``max(sigma, tau)``: a robot
    whose geometry departs from its nominal table by more than the default prior allows is
    not pulled back, while a poorly determined parameter (large ``var``) does not widen it.
    """
    cm = state.model
    free = state.free & problem.kinematic
    fidx = np.flatnonzero(free)
    blk = problem.evaluations(cm, x, state.weights, jacobian=True)
    scales = cm.layout.scales[fidx]
    JtJ, _ = block_normal(blk, fidx, scales)
    dof = max(blk.r.size - fidx.size, 1)
    s0sq = float(np.sum(blk.r**2)) / dof
    var = s0sq * np.diag(psd_inverse(JtJ, 1e-12)) * scales**2
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
        tau2 = float(np.mean(dx**2 - var[sel]))  # Eq. (T-8)
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


@dataclass(frozen=True, eq=False, repr=False)
class EvidencePriors(Record):
    """Scale the priors of the transmission, payload and link-weight terms and of the
    joint geometry (lengths, angles) by maximum evidence (:func:`evidence_prior`) and,
    when a scale changed, fit again with them (every free parameter)."""

    name: str = "stage 3: all (evidence priors)"
    # False: only the scaled priors, the parameters as they are (``--model auto``'s
    # folds then fit with them from there).
    refit: bool = True
    settings: PriorSettings | None = None  # None: from the problem's options

    def __call__(self, problem: Problem, state: State) -> State:
        prior = state.active_prior()
        opts = self.settings or PriorSettings.of(problem.options)
        if prior is None or not opts.adapt_priors:
            return state
        lm3 = replace(state.lm, max_iter=max(state.lm.max_iter, 200))
        prior, chosen = evidence_prior(problem, state, prior)
        state = state.but(prior=prior, prior_factors=chosen)
        if self.refit and any(f != 1.0 for f in chosen.values()):
            log.info("prior scales from the evidence: %s", chosen)
            state, res = run_lm(
                problem, state, self.name, state.x, state.free, lm3, prior, lifted=True
            )
            state = state.but(x=res.x)
        return state


def evidence_prior(
    problem: Problem, state: State, prior: Prior
) -> tuple[Prior, dict[str, float]]:
    """Prior scales of the transmission, compliance and joint-geometry groups by maximum
    evidence.

    With the model linearised at the state's parameters (whitened residuals ``r``,
    Jacobian ``J``) and the prior ``N(m, S)``, the data are Gaussian with covariance
    ``I + J S Jᵀ`` about the prediction at ``m``; its log density (the evidence, Eq. (T-9))
    is evaluated through Woodbury's identity for each candidate scale of a group's sigmas,
    by coordinate ascent over the groups. A group the data do not support gets a smaller
    prior (it is shrunk towards zero, or towards nominal for the geometry: at most to a
    tenth), one they do support keeps or widens it (at most 3x). Parameters without a
    prior enter with a very wide one, the same for every candidate, so they do not bias
    the comparison. With a robust loss the rows carry their IRLS weights.
    """
    cm, x, lm = state.model, state.x, state.lm
    fidx = np.flatnonzero(state.free)
    groups = np.array([evidence_group(sp) for sp in (cm.layout.specs[i] for i in fidx)])
    tune = [
        g
        for g in _EVIDENCE_GROUPS
        if np.any((groups == g) & np.isfinite(prior.sigma[fidx]))
    ]
    if not tune:
        return prior, {}
    blk = problem.evaluations(cm, x, state.weights, jacobian=True)
    sc = cm.layout.scales[fidx]
    sw = np.sqrt(loss_weights(np.sum(blk.r**2, axis=1) / lm.f_scale**2, lm.loss)[1])
    JtJ, Jtr = block_normal(blk, fidx, sc, None if lm.loss == "linear" else sw)
    # b = r + J (m - x): the data about the prediction at the prior mean
    d = (prior.mean[fidx] - x[fidx]) / sc
    Jtb = Jtr + JtJ @ d
    btb = float(np.sum((blk.r * sw[:, None]) ** 2) + 2.0 * (Jtr @ d) + d @ JtJ @ d)
    base_var = np.where(
        np.isfinite(prior.sigma[fidx]), (prior.sigma[fidx] / sc) ** 2, 1e8
    )

    def log_evidence(var: Float) -> list[float]:
        # Eq. (T-9): -1/2 (b^T (I + J S J^T)^-1 b + log det(I + J S J^T)), by Woodbury,
        # for a stack of candidate variances (K, n): the factorisations and solves in
        # one call each (LAPACK on each matrix as alone: the same numbers), the sums
        # per candidate as before.
        M = JtJ + (1.0 / var)[:, :, None] * eye
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:  # one of them failed: each alone
            return [_one(m, v) for m, v in zip(M, var)]
        Y = np.linalg.solve(L, np.broadcast_to(Jtb[:, None], (len(var), Jtb.size, 1)))
        return [_value(y[:, 0], lk, v) for y, lk, v in zip(Y, L, var)]

    def _value(y: np.ndarray, L: np.ndarray, var: np.ndarray) -> float:
        quad = btb - float(y @ y)
        logdet = float(np.sum(np.log(var))) + 2.0 * float(np.sum(np.log(np.diag(L))))
        return -0.5 * (quad + logdet)

    def _one(M: Float, var: Float) -> float:
        try:
            L = np.linalg.cholesky(M)
        except np.linalg.LinAlgError:
            return -np.inf
        return _value(np.linalg.solve(L, Jtb), L, var)

    eye = np.eye(fidx.size)
    factors = {g: 1.0 for g in tune}

    def variance(change: dict[str, float] | None = None) -> Float:
        v = base_var.copy()
        for g, f in {**factors, **(change or {})}.items():
            v[groups == g] *= f * f
        return v

    def change(g: str, f: float) -> dict[str, float]:
        # The link terms act only through the compliances (deflection = lambda * their
        # torque): shrinking the compliances takes them along, or, linearised, the link
        # terms would stand in for compliances the refit then leaves at zero.
        out = {g: f}
        if g == "load" and "link" in factors:
            tied = float(np.clip(factors["link"] * f / factors[g], 0.01, 3.0))
            out["link"] = float(f"{tied:.12g}")
        return out

    for _ in range(2):  # coordinate ascent
        for g in tune:
            cands = _GEOMETRY_FACTORS if g.startswith("joint") else _EVIDENCE_FACTORS
            le = log_evidence(
                np.array([variance()] + [variance(change(g, f)) for f in cands])
            )
            best = (le[0], factors[g])
            for f, value in zip(cands, le[1:]):
                if value > best[0] + 1e-9:
                    best = (value, f)
            factors.update(change(g, best[1]))
    sigma = prior.sigma.copy()
    all_groups = np.array([evidence_group(sp) for sp in cm.layout.specs])
    for g, f in factors.items():
        sel = (all_groups == g) & np.isfinite(sigma)
        sigma[sel] *= f
    return Prior(prior.mean, sigma), factors


def evidence_group(spec: ParamSpec) -> str:
    """The group whose priors the evidence scales together: the joint geometry by kind
    (``'joint:length'``, ``'joint:angle'``), the others by group (``'ntm'``, ``'load'``,
    ``'link'``)."""
    return f"joint:{spec.kind}" if spec.group == "joint" else spec.group
