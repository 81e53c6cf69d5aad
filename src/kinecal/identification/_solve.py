"""One solver run of a stage, logged.

:func:`run_lm` is what every non-linear stage calls: Levenberg-Marquardt on the problem's
residuals over the free parameters, optionally from the lifted start (:mod:`._lift`), with a
:class:`StageLog` and, when it did not converge, a ``not_converged`` diagnostic naming
where the estimate still drifts.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from kinecal._log import Logger
from kinecal._record import Record
from kinecal.identification._frame_fit import FrameFit
from kinecal.identification._lift import lifted_start
from kinecal.identification._lm import (
    LMCheckpoint,
    LMOptions,
    LMResult,
    NormalSource,
    Prior,
    objective,
    solve_lm,
    spd_solve,
)
from kinecal.identification._options import MU0_WARM
from kinecal.identification._problem import RETAIN_BYTES, Problem, State, nbytes
from kinecal.measurement._diagnostics import Diagnostic, StageLog
from kinecal.measurement._residuals import ResidualBlock, Weights
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = ["SolverRun", "active_prior", "lift_kept", "run_lm", "warm_options"]

log = Logger(__name__)


def run_lm(
    problem: Problem,
    state: State,
    name: str,
    x0: Float,
    free: np.ndarray,
    lm: LMOptions,
    prior: Prior | None = None,
    *,
    required: bool = True,
    lifted: bool = False,
    resume: object | None = None,
    final_jacobian: bool = True,
    evaluate: FrameFit | None = None,
    products: bool = False,
    lift_at: Float | None = None,
) -> tuple[State, LMResult]:
    """Levenberg-Marquardt over ``free`` from ``x0`` with the state's model and weights.

    Parameters
    ----------
    required : bool
        Whether non-convergence makes the calibration unsuccessful (a pre-fit is not).
    lifted : bool
        Start from the lifted start of the link products (:func:`lifted_start`), kept
        only where it does not raise the cost, with little initial damping.
    resume : SolverRun, optional
        A run of this fit with a larger ``stol`` (:attr:`State.prefit`): continued,
        where it is of this fit, instead of run again (the same iterates).
    final_jacobian : bool
        False: no Jacobian at the solution unless asked for (:func:`solve_lm`).
    evaluate : FrameFit, optional, in place of the problem's evaluations.
    products : Jacobians with product columns (a later lifted stage linearises here).
    lift_at : where the lifted start linearises (:func:`lift_kept`; default ``x0``).

    Returns
    -------
    state : the state with the run's :class:`StageLog` (and a ``not_converged``
        diagnostic); its parameters are unchanged.
    result : LMResult
    """
    ev, cm, w = evaluate or problem.evaluations, state.model, state.weights
    before = ev.rms_mm(cm, x0, w)
    problem.progress(name, f"{int(free.sum())} parameters")
    t0 = time.perf_counter()
    if lifted:
        x0 = lift_kept(problem, cm, x0, free, lm, w, prior, at=lift_at)
        lm = replace(lm, mu0=MU0_WARM)

    ck = None
    if isinstance(resume, SolverRun) and resume.serves(cm, x0, free, w, lm, prior):
        ck = resume.checkpoint
        if resume.block is not None:  # its last evaluation, for the runs after it
            problem.evaluations.put(cm, ck.x, w, resume.block)

    def fun(x: Float, jac: bool) -> tuple[Float, Float | NormalSource | None]:
        # A lifted stage's Jacobians carry the product columns (served from the cache).
        blk = ev(cm, x, w, jacobian=jac, products=lifted or products)
        return blk.r, blk.jacobian

    res = solve_lm(
        fun,
        x0,
        free,
        cm.layout.scales,
        lm,
        prior=prior,
        label=name,
        on_iteration=lambda it, c, ch: problem.progress.iteration(name, it, c, ch),
        resume=None if lifted else ck,
        final_jacobian=final_jacobian,
    )
    after = ev.rms_mm(cm, res.x, w)
    entry = StageLog(
        name,
        int(free.sum()),
        before,
        after,
        res.n_iter,
        res.status,
        res.success or not required,
        time.perf_counter() - t0,
        res.log,
    )
    msg = "%s: rms %.4f -> %.4f mm (%s, %d it)"
    log.info(msg, name, before, after, res.status, res.n_iter)
    out = state.but(stages=(*state.stages, entry))
    if not res.success and required:
        drift, where = _drift(cm, res, free, problem.options.priors)
        out = out.note(
            Diagnostic(
                "not_converged",
                f"{name} did not converge: {res.message}{drift}.",
                parameters=where,
                stage=name,
            )
        )
    return out, res


@dataclass(frozen=True, eq=False, repr=False)
class SolverRun(Record):
    """A :func:`run_lm` run without priors that stopped on its statistical tolerance,
    for a run of the same fit with a smaller one to continue (issue 36: the stage-1
    fit without priors of the rejection's robust probe and of the nominal check goes on
    from the priors' pre-fit instead of repeating its iterations)."""

    model: CalibrationModel
    x0: bytes
    free: bytes
    weights: Weights
    lm: LMOptions
    checkpoint: LMCheckpoint
    block: ResidualBlock | None  # the evaluation at the checkpoint, its Jacobian held

    @classmethod
    def of(
        cls,
        problem: Problem,
        state: State,
        x0: Float,
        free: np.ndarray,
        lm: LMOptions,
        res: LMResult,
    ) -> SolverRun | None:
        """The run ``res`` (of ``state``'s model and weights from ``x0``, no prior),
        when it stopped on ``stol`` and what it keeps takes at most RETAIN_BYTES."""
        ck = res.checkpoint
        if ck is None or not isinstance(ck.J, np.ndarray):
            return None
        cm, w = state.model, state.weights
        block = None if ck.stale else problem.evaluations.kept(cm, ck.x, w)
        if ck.J.nbytes + (0 if block is None else nbytes(block)) > RETAIN_BYTES:
            return None
        x0b, fb = np.asarray(x0, np.float64).tobytes(), np.asarray(free).tobytes()
        return cls(cm, x0b, fb, w, lm, ck, block)

    def serves(
        self,
        cm: CalibrationModel,
        x0: Float,
        free: np.ndarray,
        w: Weights,
        lm: LMOptions,
        prior: Prior | None,
    ) -> bool:
        """Whether a run of ``cm`` from ``x0`` over ``free`` under ``w`` with ``lm``
        and ``prior`` is this one's fit with at most its ``stol``."""
        return (
            prior is None
            and cm is self.model
            and w is self.weights
            and lm.stol <= self.lm.stol
            and replace(lm, stol=0.0) == replace(self.lm, stol=0.0)
            and np.asarray(x0, np.float64).tobytes() == self.x0
            and np.asarray(free).tobytes() == self.free
        )


def lift_kept(
    problem: Problem,
    cm: CalibrationModel,
    x0: Float,
    free: np.ndarray,
    lm: LMOptions,
    w: Weights,
    prior: Prior | None,
    *,
    at: Float | None = None,
) -> Float:
    """The lifted start (:mod:`._lift`), kept where it does not raise the cost.

    It linearises at ``at`` where a Jacobian with the product columns is kept there
    (stage 2's point, stage 1's solution: stage 2 is linear there and the lifted
    Gauss-Newton step takes its step in; issue 36, one Jacobian pass fewer), else at
    ``x0``."""
    if not any(free[a] and free[b] for a, b in cm.link_products):
        return x0
    ev = problem.evaluations
    n_all = cm.size + len(cm.link_products)
    blk = None if at is None else ev.kept(cm, at, w, n_all)
    x_lin = x0 if at is None else at
    if blk is None:
        x_lin, blk = x0, ev(cm, x0, w, jacobian=True, products=True)
    J = blk.jacobian
    assert J is not None
    drho = objective(blk.r, lm)[1]
    cost0 = objective(ev(cm, x0, w).r, lm)[0]  # (blk's own where at is x0)
    sw = None if lm.loss == "linear" else np.sqrt(drho)
    s0sq = 2.0 * cost0 / max(blk.r.size - int(free.sum()), 1)
    x1 = lifted_start(cm, x_lin, blk.r, J, free, prior, sw, stol=lm.stol, s0sq=s0sq)
    # With the Jacobian the stage's LM starts with (served from the cache then).
    cost1 = objective(ev(cm, x1, w, jacobian=True, products=True).r, lm)[0]
    if prior is not None:
        cost0, cost1 = cost0 + prior.cost(x0), cost1 + prior.cost(x1)
    return x1 if cost1 <= cost0 else x0


def _drift(
    cm: CalibrationModel, res: LMResult, free: np.ndarray, priors: str
) -> tuple[str, tuple[str, ...]]:
    """Where a run that hit its iteration limit was still going: the parameters that
    dominate the remaining Gauss-Newton step (in characteristic units), with their
    values. Such a run crawls down a long valley, typically a term the poses hardly
    determine (a joint compliance whose torque stays small at every pose, say)."""
    if res.status != "max_iter" or res.gradient.size == 0:
        return "", ()
    dz = -spd_solve(res.normal_matrix, res.gradient, rcond=1e-14)
    size = np.abs(dz)
    if not np.isfinite(size).all() or size.max() == 0.0:
        return "", ()
    fidx = np.flatnonzero(free)
    lead = [k for k in np.argsort(-size)[:3] if size[k] >= 0.3 * size.max()]
    parts, names = [], []
    for k in lead:
        spec = cm.layout.specs[fidx[k]]
        unit = spec.unit
        names.append(spec.name)
        parts.append(
            f"{spec.name} (now {res.x[fidx[k]] * unit.to_file:.4g} {unit.file_unit})"
        )
    text = "; the estimate still drifts along " + ", ".join(parts)
    text += ", which these poses hardly determine"
    if priors != "all":
        text += " (the default priors, --priors all, hold such terms)"
    return text, tuple(names)


# Iterations a fit from a warm start may take (more than a stage from a good start).
_WARM_MAX_ITER = 200


def warm_options(lm: LMOptions) -> LMOptions:
    """The solver options from a start next to the optimum: little initial damping
    (:data:`MU0_WARM`), and at least 200 iterations."""
    return replace(lm, max_iter=max(lm.max_iter, _WARM_MAX_ITER), mu0=MU0_WARM)


def active_prior(prior: Prior, free: np.ndarray) -> Prior | None:
    """The prior, or None when it holds none of the free parameters."""
    return prior if np.any(np.isfinite(prior.sigma) & free) else None
