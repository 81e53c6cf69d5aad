"""Levenberg-Marquardt least squares with scaling, robust losses and an iteration log.

Minimises ``1/2 sum_i f^2 rho(|r_i|^2 / f^2) + 1/2 sum_k ((x_k - m_k) / s_k)^2`` over the
free parameters, where ``r_i`` is the residual block of row i (3 or 6 components, already
whitened) and the second sum is an optional Gaussian prior (MAP estimation; parameters
without a prior have ``s_k = inf``). Each iteration solves

.. math:: (J_s^T W J_s + \\mu\\, \\mathrm{diag}(J_s^T W J_s))\\, \\delta z = -J_s^T W r

in scaled variables ``z = (x - x_0) / s`` (``s``: characteristic size of each parameter,
so millimetres and radians are comparable), accepts the step when the gain ratio is
positive and adapts ``mu`` (Nielsen's rule). Robust losses enter by iteratively reweighted
least squares on whole rows, so an outlying pose is down-weighted, not a single axis.

The paper's fixed-step update (``eta += 0.005 · GN step``, Sec. 4) is
:func:`~kinecal.identification._fixed_step.solve_fixed_step`, kept only as a benchmark
baseline.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from kinecal._log import Logger
from kinecal._record import MutableRecord, Record
from kinecal.identification._lm_entry import check_first_evaluation, checked_start
from kinecal.identification._normal import NormalSource, normal_equations, normal_of
from kinecal.typing import Float

__all__ = [
    "LOSSES",
    "LMOptions",
    "LMResult",
    "NormalSource",
    "Prior",
    "loss_weights",
    "normal_equations",
    "normal_of",
    "objective",
    "psd_inverse",
    "solve_lm",
    "spd_solve",
]

log = Logger(__name__)

LOSSES = ("linear", "huber", "soft_l1")

ResidualFn = Callable[[Float, bool], tuple[Float, "Float | NormalSource | None"]]


@dataclass(frozen=True, eq=False, repr=False)
class LMOptions(Record):
    """Solver settings.

    Attributes
    ----------
    max_iter : int
        Jacobian evaluations at most.
    ftol, xtol, gtol : float
        Stop when the relative cost decrease, the relative scaled step, or the largest
        scaled gradient entry (relative to the cost) falls below these.
    loss : {'linear', 'huber', 'soft_l1'}
    f_scale : float
        Residual-norm scale (whitened units) where a robust loss starts to bend.
    mu0 : float
        Initial damping (relative to the diagonal of the normal matrix).
    stol : float
        Statistical tolerance: also stop when an accepted step lowered the cost by at most
        ``stol`` times the a-posteriori variance of unit weight, ``2 cost / (m - k)`` (m
        residuals, k free parameters), or when the undamped Gauss-Newton step from the
        current point would (so no step is taken). Such a step moves the estimate by
        about ``sqrt(2 stol)`` of its standard deviations, a criterion that does not
        tighten with the number of residuals. 0 (the default) turns it off.
    """

    max_iter: int = 100
    ftol: float = 1e-10
    xtol: float = 1e-10
    gtol: float = 1e-10
    loss: str = "linear"
    f_scale: float = 1.0
    mu0: float = 1e-3
    stol: float = 0.0

    def __post_init__(self) -> None:
        if self.loss not in LOSSES:
            raise ValueError(f"loss must be one of {LOSSES}; got {self.loss!r}.")
        if self.f_scale <= 0:
            raise ValueError(f"f_scale must be positive; got {self.f_scale}.")


@dataclass(frozen=True, eq=False, repr=False)
class LMCheckpoint(Record):
    """Where a :func:`solve_lm` run stopped on its statistical tolerance ``stol``: the
    state a run from the same start with a smaller ``stol`` continues from (its
    iterates up to there are the same; ``solve_lm(..., resume=)``, issue 36).
    ``where``: 'top', the Gauss-Newton test at the start of iteration ``it``, or
    'accept', the test after its step (decrease ``dcost``)."""

    stol: float
    where: str
    it: int
    x: Float
    r: Float
    J: object
    stale: bool
    cost: float
    w: Float
    mu: float
    nu: float
    trust: bool
    n_eval: int
    history: tuple[dict[str, float], ...]
    dcost: float = 0.0


@dataclass(eq=False, repr=False)
class LMResult(MutableRecord):
    """Outcome of :func:`solve_lm`.

    ``normal_matrix`` is ``J_s^T W J_s`` of the free parameters in scaled variables at the
    solution (computed when first asked for: for large data a pass over every pose) and
    ``gradient`` its ``J_s^T W r``; ``row_weights`` are the robust weights of the rows (1
    for the linear loss).
    """

    x: Float
    cost: float
    n_iter: int
    n_eval: int
    success: bool
    status: str
    message: str
    _normal: Float | Callable[[], tuple[Float, Float]]
    _gradient: Float | None
    row_weights: Float
    residual: Float
    log: list[dict[str, float]] = field(default_factory=list)
    seconds: float = 0.0
    checkpoint: LMCheckpoint | None = None  # where a stop on ``stol`` was decided

    @property
    def normal_matrix(self) -> Float:
        if callable(self._normal):
            self._normal, self._gradient = self._normal()
        return self._normal

    @property
    def gradient(self) -> Float:
        self.normal_matrix  # noqa: B018 - computes both
        assert self._gradient is not None
        return self._gradient


def loss_weights(z: Float, loss: str) -> tuple[Float, Float]:
    """``rho(z)`` and ``rho'(z)`` for squared normalised row norms ``z``."""
    if loss == "linear":
        return z, np.ones_like(z)
    if loss == "huber":
        big = z > 1.0
        sq = np.sqrt(np.where(big, z, 1.0))
        return np.where(big, 2.0 * sq - 1.0, z), np.where(big, 1.0 / sq, 1.0)
    if loss == "soft_l1":
        t = np.sqrt(1.0 + z)
        return 2.0 * (t - 1.0), 1.0 / t
    raise ValueError(f"unknown loss {loss!r}")


def spd_solve(M: Float, b: Float, rcond: float | None = None) -> Float:
    """``M⁻¹ b`` for a symmetric positive (semi-)definite M: by Cholesky, or by least
    squares (singular values below ``rcond`` of the largest cut) where M is singular."""
    try:
        L = np.linalg.cholesky(M)
        return np.asarray(np.linalg.solve(L.T, np.linalg.solve(L, b)), np.float64)
    except np.linalg.LinAlgError:
        return np.asarray(np.linalg.lstsq(M, b, rcond=rcond)[0], np.float64)


def psd_inverse(A: Float, rcond: float) -> Float:
    """Pseudo-inverse of a symmetric positive semi-definite matrix, eigenvalues below
    ``rcond`` times the largest left out."""
    evals, evecs = np.linalg.eigh(A)
    good = evals > evals.max() * rcond
    return (evecs[:, good] / evals[good]) @ evecs[:, good].T


def objective(r: Float, opts: LMOptions) -> tuple[float, Float]:
    """The data part of the cost, ``1/2 sum_i f^2 rho(|r_i|^2 / f^2)``, and the robust
    weight ``rho'`` of every row (N,)."""
    f2 = opts.f_scale**2
    z = np.sum(r * r, axis=1) / f2
    rho, drho = loss_weights(z, opts.loss)
    return 0.5 * f2 * float(np.sum(rho)), drho


@dataclass(frozen=True, eq=False, repr=False)
class Prior(Record):
    """Independent Gaussian priors ``x_k ~ N(mean_k, sigma_k^2)``; ``inf``: no prior."""

    mean: Float
    sigma: Float

    @classmethod
    def none(cls, size: int) -> Prior:
        return cls(np.zeros(size), np.full(size, np.inf))

    def cost(self, x: Float) -> float:
        d = (x - self.mean) / self.sigma
        # Eq. (T-6): the prior term of the MAP objective
        return 0.5 * float(np.sum(np.where(np.isfinite(self.sigma), d * d, 0.0)))

    @property
    def precision(self) -> Float:
        return np.where(np.isfinite(self.sigma), 1.0 / self.sigma**2, 0.0)


def solve_lm(
    fun: ResidualFn,
    x0: Float,
    free: np.ndarray,
    scales: Float,
    options: LMOptions | None = None,
    *,
    prior: Prior | None = None,
    label: str = "lm",
    on_iteration: Callable[[int, float, float], None] | None = None,
    s0sq: float | None = None,
    resume: LMCheckpoint | None = None,
    final_jacobian: bool = True,
) -> LMResult:
    """Levenberg-Marquardt on ``fun`` over the parameters flagged in ``free``.

    Parameters
    ----------
    fun : callable ``fun(x, jacobian) -> (r (N, c), J (N, c, P) or None)``
        Whitened residual rows and their Jacobian w.r.t. the full parameter vector.
    x0 : (P,) start
    free : (P,) bool, which parameters move
    scales : (P,) characteristic size of each parameter (SI)
    options : LMOptions
    prior : Prior, optional (MAP estimation)
    label : str, name used in the log
    on_iteration : callable ``on_iteration(it, cost, relative change)``, optional
        Called after each iteration (for progress displays).
    s0sq : float, optional
        The variance of unit weight the statistical stop (``stol``) compares with;
        default ``2 cost / (m - k)`` of the residuals at hand (a sub-problem such as the
        lifted start passes its parent's).
    resume : LMCheckpoint, optional
        Where a run of the same problem from ``x0`` with a larger ``stol`` stopped
        (:attr:`LMResult.checkpoint`): this run continues from there, with the iterates
        a run from ``x0`` takes (ignored for a larger ``stol`` than its own).
    final_jacobian : bool
        False: no Jacobian at the point where the run ends unless ``normal_matrix`` is
        asked for (a fit whose Jacobian there nobody reads: one pass fewer).

    Returns
    -------
    LMResult
        Non-convergence is reported in ``success``/``status``, never raised.

    The Jacobian at an accepted point is asked for when the next iteration needs it, or
    when the run ends there (the next stage starts from it).
    """
    opts = options or LMOptions()
    t0 = time.perf_counter()
    x, free, scales = checked_start(x0, free, scales)
    if resume is not None and opts.stol <= resume.stol:
        obj = _Objective.make(fun, free, scales, opts, prior, s0sq, resume.r.size)
        run = _Run(obj, label, final_jacobian)
        first = run.restore(resume)
    else:
        r, J = fun(x, True)
        check_first_evaluation(r, J, x.size)
        assert J is not None
        obj = _Objective.make(fun, free, scales, opts, prior, s0sq, r.size)
        run = _Run(obj, label, final_jacobian)
        run.start(x, r, J)
        first = 1
    for it in range(first, opts.max_iter + 1 if first else 0):
        if run.iterate(it, on_iteration):
            break
    else:
        run.at_end()  # the Jacobian at the last point, where the next stage starts
    return run.result(time.perf_counter() - t0)


@dataclass(eq=False, repr=False)
class _Objective(MutableRecord):
    """What :func:`solve_lm` minimises: the data term of ``fun``'s residuals and the
    prior, over the free parameters ``fidx`` in scaled variables (``x = x0 + s z``)."""

    fun: ResidualFn
    opts: LMOptions
    prior: Prior | None
    fidx: np.ndarray
    s: Float
    prec: Float  # prior precision in scaled variables
    s0sq: float | None
    m: int  # residual components

    @classmethod
    def make(
        cls,
        fun: ResidualFn,
        free: np.ndarray,
        scales: Float,
        opts: LMOptions,
        prior: Prior | None,
        s0sq: float | None,
        m: int,
    ) -> _Objective:
        fidx = np.flatnonzero(free)
        s = scales[fidx]
        pr = prior or Prior.none(free.size)
        return cls(fun, opts, prior, fidx, s, pr.precision[fidx] * s * s, s0sq, m)

    def unit(self, c: float) -> float:
        """The variance of unit weight the statistical stop compares with."""
        if self.s0sq is not None:
            return self.s0sq
        return 2.0 * c / max(self.m - self.fidx.size, 1)

    def cost(self, x: Float, r: Float) -> tuple[float, Float]:
        """The total cost at ``x`` (residuals ``r``) and the robust row weights."""
        c, w = objective(r, self.opts)
        return (c + self.prior.cost(x) if self.prior is not None else c), w

    def normal(
        self, x: Float, r: Float, J: Float | NormalSource, w: Float
    ) -> tuple[Float, Float]:
        """Normal matrix and gradient in scaled variables, with the prior."""
        sw = None if self.opts.loss == "linear" else np.sqrt(w)
        A, g = normal_of(r, J, self.fidx, self.s, sw)
        A += np.diag(self.prec)  # the prior of Eq. (T-6), in scaled variables
        if self.prior is not None:
            g = g + self.prec * (x[self.fidx] - self.prior.mean[self.fidx]) / self.s
        return A, g

    def trial(self, x: Float, dz: Float) -> tuple[Float, Float, float, Float]:
        """The point ``x + s dz``: its parameters, residuals, cost and row weights."""
        x_new = x.copy()
        x_new[self.fidx] += dz * self.s
        r_new, _ = self.fun(x_new, False)
        cost_new, w_new = self.cost(x_new, r_new)
        return x_new, r_new, cost_new, w_new


class _Run:
    """The iterations of one :func:`solve_lm` run: the accepted point, its Jacobian
    (asked for when an iteration needs it), the damping (Nielsen's rule) and the log."""

    def __init__(self, obj: _Objective, label: str, final_jacobian: bool) -> None:
        self.obj, self.label, self.final_jacobian = obj, label, final_jacobian
        self.mu, self.nu = obj.opts.mu0, 2.0
        self.trust = False  # the last step's model predicted its decrease well
        self.n_eval, self.it = 1, 0
        self.history: list[dict[str, float]] = []
        self.status, self.success = "max_iter", False
        self.message = f"{label}: stopped after {obj.opts.max_iter} iterations"
        k = obj.fidx.size
        self.A, self.g = np.zeros((k, k)), np.zeros(k)
        self.final: Callable[[], tuple[Float, Float]] | None = None
        self.checkpoint: LMCheckpoint | None = None

    def start(self, x: Float, r: Float, J: Float | NormalSource) -> None:
        self.x, self.r, self.J, self.stale = x, r, J, False
        self.cost, self.w = self.obj.cost(x, r)

    def _end(self, status: str, message: str, success: bool) -> bool:
        self.status, self.message, self.success = status, message, success
        return True

    def iterate(
        self, it: int, on_iteration: Callable[[int, float, float], None] | None
    ) -> bool:
        """Iteration ``it``; True when the run ends."""
        obj, opts = self.obj, self.obj.opts
        self.it = it
        self._jacobian()  # at the accepted point, needed now
        A, g = self.A, self.g = obj.normal(self.x, self.r, self.J, self.w)
        gnorm = float(np.abs(g).max()) if g.size else 0.0
        if gnorm <= opts.gtol * max(self.cost, 1e-300) or obj.fidx.size == 0:
            return self._end("gtol", f"{self.label}: gradient vanished", True)
        accepted, new, dz, rho = False, None, np.zeros(0), -1.0
        if opts.stol > 0:
            dz, pred = _gauss_newton(A, g)
            if pred <= opts.stol * obj.unit(self.cost):
                self.checkpoint = self._snapshot("top", it)
                self.it = it - 1  # no step taken in this iteration
                msg = f"{self.label}: converged (stol) after {it - 1} iterations"
                return self._end("stol", msg, True)
            if self.trust:  # the last step's model held: the undamped step first
                new = obj.trial(self.x, dz)
                self.n_eval += 1
                rho = float((self.cost - new[2]) / pred)
                accepted = bool(np.isfinite(new[2])) and rho > 0.75
                if accepted:
                    self.mu = max(self.mu / 10.0, 1e-15)
        if not accepted:
            accepted, new, dz, rho = self._damped(A, g)
        assert new is not None
        self._log(it, accepted, new[2], dz, rho, on_iteration)
        if not accepted:
            return self._stalled(A, g)
        return self._accept(new, dz, rho)

    def _damped(
        self, A: Float, g: Float
    ) -> tuple[bool, tuple[Float, Float, float, Float], Float, float]:
        """Damped steps, the damping raised until one lowers the cost (or beyond 1e16)."""
        diag = np.diag(A).copy()
        diag = np.maximum(diag, 1e-12 * max(float(diag.max()), 1e-300))
        while True:
            dz = -spd_solve(A + self.mu * np.diag(diag), g)
            new = self.obj.trial(self.x, dz)
            self.n_eval += 1
            pred = -float(g @ dz + 0.5 * dz @ (A @ dz))
            actual = self.cost - new[2]
            rho = float(actual / pred) if pred > 0 else -1.0
            if np.isfinite(new[2]) and rho > 0:
                self.mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                self.nu = 2.0
                return True, new, dz, rho
            self.mu *= self.nu
            self.nu *= 2.0
            if self.mu > 1e16:
                return False, new, dz, rho

    def _log(
        self,
        it: int,
        accepted: bool,
        cost_new: float,
        dz: Float,
        rho: float,
        on_iteration: Callable[[int, float, float], None] | None,
    ) -> None:
        cost = self.cost
        self.history.append(
            {
                "iter": it,
                "cost": cost,
                "cost_new": cost_new if accepted else cost,
                "mu": float(self.mu),
                "step": float(np.linalg.norm(dz)),
                "gain": float(rho),
            }
        )
        log.debug(
            "%s it %d cost %.6g -> %.6g mu %.2e",
            self.label,
            it,
            cost,
            cost_new,
            self.mu,
        )
        if on_iteration is not None and accepted:
            on_iteration(it, cost_new, (cost_new - cost) / max(abs(cost), 1e-300))

    def _stalled(self, A: Float, g: Float) -> bool:
        """No step helps. That is convergence when even the undamped Gauss-Newton step
        promises a decrease at the level of round-off in the cost."""
        cost, label = self.cost, self.label
        try:
            dz_gn = np.linalg.lstsq(A, -g, rcond=1e-14)[0]
            pred_gn = float(-(g @ dz_gn + 0.5 * dz_gn @ (A @ dz_gn)))
        except np.linalg.LinAlgError:
            pred_gn = float("inf")
        log.debug(
            "%s stalled: Gauss-Newton would gain %.3g of %.3g", label, pred_gn, cost
        )
        if pred_gn <= 1e-9 * max(cost, 1e-300) or cost == 0.0:
            msg = f"{label}: converged (no further decrease above round-off)"
            return self._end("stalled", msg, True)
        msg = f"{label}: no step reduces the cost (damping {self.mu:.1e})"
        return self._end("stalled", msg, False)

    def _accept(
        self, new: tuple[Float, Float, float, Float], dz: Float, rho: float
    ) -> bool:
        """Move to the accepted point; True when a convergence test ends the run."""
        obj, opts = self.obj, self.obj.opts
        self.trust = rho > 0.75
        dcost = self.cost - new[2]
        step_small = np.linalg.norm(dz) <= opts.xtol * (
            np.linalg.norm(self.x[obj.fidx] / obj.s) + opts.xtol
        )
        self.x, self.r, self.cost, self.w = new
        self.stale = True
        converged = (
            "ftol"
            if dcost <= opts.ftol * self.cost
            else "xtol"
            if step_small
            else "stol"
            if dcost <= opts.stol * obj.unit(self.cost)
            else None
        )
        if converged is None:
            return False
        self.at_end()  # at the solution: the next stage starts there
        if converged == "stol":
            self.checkpoint = self._snapshot("accept", self.it, dcost)
        # The normal matrix at the solution, computed when asked for (large data take
        # a pass over every pose for it).
        self.final = self._final_normal
        msg = f"{self.label}: converged ({converged}) after {self.it} iterations"
        return self._end(converged, msg, True)

    def at_end(self) -> None:
        """The Jacobian where the run ends, if wanted there (``final_jacobian``)."""
        if self.final_jacobian:
            self._jacobian()

    def _final_normal(self) -> tuple[Float, Float]:
        """The normal matrix and gradient at the solution (its Jacobian evaluated now
        if the run did not)."""
        self._jacobian()
        return self.obj.normal(self.x, self.r, self.J, self.w)

    def _jacobian(self) -> None:
        """The Jacobian (and residuals) at the accepted point, if not yet evaluated."""
        if self.stale:
            self.r, J1 = self.obj.fun(self.x, True)
            self.n_eval += 1
            self.J = J1 if J1 is not None else self.J
            self.stale = False

    def _snapshot(self, where: str, it: int, dcost: float = 0.0) -> LMCheckpoint:
        return LMCheckpoint(
            self.obj.opts.stol,
            where,
            it,
            self.x,
            self.r,
            self.J,
            self.stale,
            self.cost,
            self.w,
            self.mu,
            self.nu,
            self.trust,
            self.n_eval,
            tuple(self.history),
            dcost,
        )

    def restore(self, ck: LMCheckpoint) -> int:
        """The state at ``ck``; the iteration to go on with (0: converged there)."""
        self.x, self.r, self.stale = ck.x, ck.r, ck.stale
        self.cost, self.w = ck.cost, ck.w
        self.J = ck.J  # type: ignore[assignment]
        self.mu, self.nu, self.trust, self.n_eval = ck.mu, ck.nu, ck.trust, ck.n_eval
        self.history = list(ck.history)
        self.it = ck.it - 1 if ck.where == "top" else ck.it
        if ck.where == "top":
            return ck.it
        # After the step: its decrease against the smaller tolerance (the ftol and
        # xtol tests, which do not depend on it, had not stopped the run).
        opts = self.obj.opts
        if ck.dcost <= opts.stol * self.obj.unit(self.cost):
            self.final = self._final_normal
            self.checkpoint = ck
            msg = f"{self.label}: converged (stol) after {self.it} iterations"
            self._end("stol", msg, True)
            return 0
        return ck.it + 1

    def result(self, seconds: float) -> LMResult:
        return LMResult(
            x=self.x,
            cost=self.cost,
            n_iter=self.it,
            n_eval=self.n_eval,
            success=self.success,
            status=self.status,
            message=self.message,
            _normal=self.final if self.final is not None else self.A,
            _gradient=None if self.final is not None else self.g,
            row_weights=self.w,
            residual=self.r,
            log=self.history,
            seconds=seconds,
            checkpoint=self.checkpoint,
        )


def _gauss_newton(A: Float, g: Float) -> tuple[Float, float]:
    """The undamped Gauss-Newton step (scaled) and the decrease of the cost its quadratic
    model predicts (``inf`` where it is not finite)."""
    dz = -spd_solve(A, g)
    pred = -float(g @ dz + 0.5 * dz @ (A @ dz))
    return dz, pred if np.isfinite(pred) else float("inf")
