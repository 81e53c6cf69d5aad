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
:func:`solve_fixed_step`, kept only as a benchmark baseline.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from kinecal.typing import ArrayLike, Float

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
    "solve_fixed_step",
    "solve_lm",
    "spd_solve",
]

log = logging.getLogger(__name__)

LOSSES = ("linear", "huber", "soft_l1")

ResidualFn = Callable[[Float, bool], tuple[Float, "Float | NormalSource | None"]]


@dataclass(frozen=True)
class LMOptions:
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


@dataclass
class LMResult:
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


class NormalSource(Protocol):
    """A Jacobian that gives its normal equations without being held
    (:class:`~kinecal.measurement._blocks.BlockJacobian`)."""

    def normal(
        self, cols: np.ndarray, scales: Float, row_weights: Float | None = None
    ) -> tuple[Float, Float]: ...


def normal_of(
    r: Float,
    J: Float | NormalSource,
    cols: np.ndarray,
    scales: Float,
    row_weights: Float | None = None,
) -> tuple[Float, Float]:
    """:func:`normal_equations` of a held Jacobian, or those a block-wise one gives."""
    if isinstance(J, np.ndarray):
        return normal_equations(r, J, cols, scales, row_weights)
    return J.normal(cols, scales, row_weights)


def normal_equations(
    r: Float,
    J: Float,
    cols: np.ndarray,
    scales: Float,
    row_weights: Float | None = None,
) -> tuple[Float, Float]:
    """``(Jsᵀ Js, Jsᵀ r)`` for the columns ``cols`` of J in scaled units.

    ``Js = J[:, :, cols] · scales`` with the rows of sample i multiplied by
    ``row_weights[i]`` (the square roots of robust weights) when given.

    Parameters
    ----------
    r : (N, c) residual rows.
    J : (N, c, P') Jacobian, any memory layout. The model's own (a view of a
        parameter-major (P', c, N) array) gives one product of contiguous rows over the
        span of ``cols``, with no copy for unweighted rows.
    cols : (k,) column indices.
    scales : (k,) characteristic size of each selected column.
    row_weights : (N,), optional.
    """
    cols = np.asarray(cols, dtype=np.intp)
    if cols.size == 0:
        return np.zeros((0, 0)), np.zeros(0)
    lo, hi = int(cols.min()), int(cols.max()) + 1
    X = J.transpose(2, 1, 0)[lo:hi]  # (span, c, N), rows in (component, sample) order
    rt = r.T
    if row_weights is not None:
        X = X * row_weights
        rt = rt * row_weights
    Xm = X.reshape(hi - lo, -1)
    A = Xm @ Xm.T
    g = Xm @ rt.reshape(-1)
    sel = cols - lo
    return A[np.ix_(sel, sel)] * np.outer(scales, scales), g[sel] * scales


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


@dataclass(frozen=True)
class Prior:
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


def _checked_start(
    x0: ArrayLike, free: ArrayLike, scales: ArrayLike
) -> tuple[Float, np.ndarray, Float]:
    """``x0``, ``free`` and ``scales`` as arrays, validated (scipy-style: a ValueError
    naming the argument and the shapes)."""
    x = np.array(x0, dtype=np.float64)
    if x.ndim != 1:
        raise ValueError(f"solve_lm: x0 must be a vector (P,); got shape {x.shape}.")
    f = np.asarray(free)
    if f.shape != x.shape:
        raise ValueError(
            f"solve_lm: free must have the shape of x0 {x.shape}; got {f.shape}."
        )
    if f.dtype != np.bool_:
        raise ValueError(f"solve_lm: free must be booleans; got dtype {f.dtype}.")
    sc = np.asarray(scales, dtype=np.float64)
    if sc.shape != x.shape:
        raise ValueError(
            f"solve_lm: scales must have the shape of x0 {x.shape}; got {sc.shape}."
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(
            f"solve_lm: x0 must be finite; entries {np.flatnonzero(~np.isfinite(x))[:5]}"
            " are not."
        )
    bad = ~(np.isfinite(sc) & (sc > 0)) & f
    if np.any(bad):
        raise ValueError(
            "solve_lm: scales of the free parameters must be finite and > 0; entries "
            f"{np.flatnonzero(bad)[:5]} are not."
        )
    return x, f, sc


def _check_first_evaluation(
    r: Any, J: Float | NormalSource | None, size: int
) -> Float | NormalSource:
    """The residuals and the Jacobian of ``fun`` at ``x0``: finite, of matching
    shapes (a NaN at the start would otherwise end as "stalled")."""
    if J is None:
        raise ValueError("solve_lm: fun(x, True) must return a Jacobian; got None.")
    r = np.asarray(r)
    if r.ndim < 1 or r.size == 0:
        raise ValueError(
            f"solve_lm: fun(x0) must return residual rows (N, c); got shape {r.shape}."
        )
    if not np.all(np.isfinite(r)):
        n_bad = int(np.count_nonzero(~np.isfinite(r)))
        raise ValueError(
            f"solve_lm: the residuals at x0 are not finite ({n_bad} of {r.size} "
            "entries NaN or inf); check the data and the start."
        )
    if isinstance(J, np.ndarray) and (
        J.shape[:-1] != r.shape or J.ndim != r.ndim + 1 or J.shape[-1] < size
    ):
        # (a lifted stage's Jacobian carries extra product columns after the P)
        raise ValueError(
            f"solve_lm: the Jacobian at x0 must have shape {(*r.shape, size)} (residuals "
            f"{r.shape} by {size} parameters of x0); got {J.shape}."
        )
    return J


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

    Returns
    -------
    LMResult
        Non-convergence is reported in ``success``/``status``, never raised.
    """
    opts = options or LMOptions()
    t0 = time.perf_counter()
    x, free, scales = _checked_start(x0, free, scales)
    fidx = np.flatnonzero(free)
    s = scales[fidx]
    pr = prior or Prior.none(x.size)
    prec = pr.precision[fidx] * s * s  # prior precision in scaled variables
    pmean = pr.mean[fidx]

    def unit(c: float) -> float:  # variance of unit weight
        return s0sq if s0sq is not None else 2.0 * c / max(r.size - fidx.size, 1)

    def total_cost(xx: Float, rr: Float) -> tuple[float, Float]:
        c, ww = objective(rr, opts)
        return c + pr.cost(xx) if prior is not None else c, ww

    def normal(
        xx: Float, rr: Float, JJ: Float | NormalSource, ww: Float
    ) -> tuple[Float, Float]:
        sw_ = None if opts.loss == "linear" else np.sqrt(ww)
        A_, g_ = normal_of(rr, JJ, fidx, s, sw_)
        A_ += np.diag(prec)  # the prior of Eq. (T-6), in scaled variables
        if prior is not None:
            g_ = g_ + prec * (xx[fidx] - pmean) / s
        return A_, g_

    r, J0 = fun(x, True)
    J: Float | NormalSource = _check_first_evaluation(r, J0, x.size)
    n_eval = 1
    cost, w = total_cost(x, r)
    mu = opts.mu0
    nu = 2.0
    history: list[dict[str, float]] = []
    status, message = "max_iter", f"{label}: stopped after {opts.max_iter} iterations"
    success = False
    A = np.zeros((fidx.size, fidx.size))
    g = np.zeros(fidx.size)
    final: Float | Callable[[], tuple[Float, Float]] = A
    trust = False  # whether the last step's quadratic model predicted its decrease well
    it = 0
    for it in range(1, opts.max_iter + 1):
        A, g = normal(x, r, J, w)
        gnorm = float(np.abs(g).max()) if g.size else 0.0
        if gnorm <= opts.gtol * max(cost, 1e-300) or fidx.size == 0:
            status, message, success = "gtol", f"{label}: gradient vanished", True
            break
        accepted = False
        if opts.stol > 0:
            dz, pred = _gauss_newton(A, g)
            if pred <= opts.stol * unit(cost):
                it -= 1  # no step taken in this iteration
                status, success = "stol", True
                message = f"{label}: converged (stol) after {it} iterations"
                break
            if trust:  # the last step's quadratic model held: the undamped step first
                x_new = x.copy()
                x_new[fidx] += dz * s
                r_new, _ = fun(x_new, False)
                n_eval += 1
                cost_new, w_new = total_cost(x_new, r_new)
                rho = float((cost - cost_new) / pred)
                accepted = bool(np.isfinite(cost_new)) and rho > 0.75
                if accepted:
                    mu = max(mu / 10.0, 1e-15)
        diag = np.diag(A).copy()
        diag = np.maximum(diag, 1e-12 * max(float(diag.max()), 1e-300))
        while not accepted:
            dz = -spd_solve(A + mu * np.diag(diag), g)
            x_new = x.copy()
            x_new[fidx] += dz * s
            r_new, _ = fun(x_new, False)
            n_eval += 1
            cost_new, w_new = total_cost(x_new, r_new)
            pred = -float(g @ dz + 0.5 * dz @ (A @ dz))
            actual = cost - cost_new
            rho = float(actual / pred) if pred > 0 else -1.0
            if np.isfinite(cost_new) and rho > 0:
                accepted = True
                mu *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
                nu = 2.0
                break
            mu *= nu
            nu *= 2.0
            if mu > 1e16:
                break
        history.append(
            {
                "iter": it,
                "cost": cost,
                "cost_new": cost_new if accepted else cost,
                "mu": float(mu),
                "step": float(np.linalg.norm(dz)),
                "gain": float(rho),
            }
        )
        log.debug("%s it %d cost %.6g -> %.6g mu %.2e", label, it, cost, cost_new, mu)
        if on_iteration is not None and accepted:
            on_iteration(it, cost_new, (cost_new - cost) / max(abs(cost), 1e-300))
        if not accepted:
            status = "stalled"
            message = f"{label}: no step reduces the cost (damping {mu:.1e})"
            # No step helps. That is convergence when even the undamped Gauss-Newton
            # step promises a decrease at the level of round-off in the cost.
            try:
                dz_gn = np.linalg.lstsq(A, -g, rcond=1e-14)[0]
                pred_gn = float(-(g @ dz_gn + 0.5 * dz_gn @ (A @ dz_gn)))
            except np.linalg.LinAlgError:
                pred_gn = float("inf")
            log.debug(
                "%s stalled: Gauss-Newton would gain %.3g of %.3g", label, pred_gn, cost
            )
            success = pred_gn <= 1e-9 * max(cost, 1e-300) or cost == 0.0
            if success:
                message = f"{label}: converged (no further decrease above round-off)"
            break
        trust = rho > 0.75
        dcost = cost - cost_new
        step_small = np.linalg.norm(dz) <= opts.xtol * (
            np.linalg.norm(x[fidx] / s) + opts.xtol
        )
        x, r, cost, w = x_new, r_new, cost_new, w_new
        converged = (
            "ftol"
            if dcost <= opts.ftol * cost
            else "xtol"
            if step_small
            else "stol"
            if dcost <= opts.stol * unit(cost)
            else None
        )
        if converged is not None:
            status = converged
            message = f"{label}: converged ({status}) after {it} iterations"
            success = True
            r, J1 = fun(x, True)
            n_eval += 1
            if J1 is not None:
                J = J1
            # The normal matrix at the solution, computed when asked for (large data
            # take a pass over every pose for it).
            final = _deferred(normal, x, r, J, w)
            break
        r, J1 = fun(x, True)
        n_eval += 1
        if J1 is not None:
            J = J1
    return LMResult(
        x=x,
        cost=cost,
        n_iter=it,
        n_eval=n_eval,
        success=success,
        status=status,
        message=message,
        _normal=final if callable(final) else A,
        _gradient=None if callable(final) else g,
        row_weights=w,
        residual=r,
        log=history,
        seconds=time.perf_counter() - t0,
    )


def _gauss_newton(A: Float, g: Float) -> tuple[Float, float]:
    """The undamped Gauss-Newton step (scaled) and the decrease of the cost its quadratic
    model predicts (``inf`` where it is not finite)."""
    dz = -spd_solve(A, g)
    pred = -float(g @ dz + 0.5 * dz @ (A @ dz))
    return dz, pred if np.isfinite(pred) else float("inf")


def _deferred(
    normal: Callable[[Float, Float, Float | NormalSource, Float], tuple[Float, Float]],
    x: Float,
    r: Float,
    J: Float | NormalSource,
    w: Float,
) -> Callable[[], tuple[Float, Float]]:
    return lambda: normal(x, r, J, w)


def solve_fixed_step(
    fun: ResidualFn,
    x0: Float,
    free: np.ndarray,
    *,
    zeta: float = 0.005,
    n_iter: int = 200,
) -> tuple[Float, list[float]]:
    """The paper's update ``eta_{k+1} = eta_k + zeta (J^T J)^-1 J^T dq`` (Sec. 4).

    A benchmark baseline only: with ``zeta = 0.005`` each iteration removes 0.5 % of the
    Gauss-Newton step, so it needs thousands of iterations to converge.

    Returns
    -------
    x : (P,) final parameters
    costs : list of ``|r|^2 / 2`` per iteration
    """
    x = np.array(x0, dtype=np.float64)
    fidx = np.flatnonzero(np.asarray(free, dtype=bool))
    costs = []
    for _ in range(n_iter):
        r, J = fun(x, True)
        assert isinstance(J, np.ndarray), "solve_fixed_step needs the Jacobian held"
        Jf = J[:, :, fidx].reshape(-1, fidx.size)
        rf = r.reshape(-1)
        costs.append(0.5 * float(rf @ rf))
        step = np.linalg.lstsq(Jf, -rf, rcond=None)[0]  # (J^T J)^-1 J^T dq, Eq. (28)
        x[fidx] += zeta * step  # the paper's update, step (3) after Eq. (28)
    return x, costs
