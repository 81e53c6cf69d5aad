"""The folds of ``--model auto``: each fold's fit from its candidate's fit on every kept
row (:mod:`._candidates`), by Newton steps on the downdated normal equations (Eq. (T-10)).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kinecal._stats import present as used
from kinecal.errors import IdentifiabilityError
from kinecal.identification._lm import Prior, spd_solve
from kinecal.identification._problem import Problem, State
from kinecal.identification._solve import active_prior, run_lm, warm_options
from kinecal.identification.selection._candidates import CandidateFit
from kinecal.identification.selection._crossval import (
    held_out_metrics,
    relabel_sets,
)
from kinecal.measurement._calibrated import CalibratedModel
from kinecal.measurement._metrics import Metrics, metrics_from_errors
from kinecal.measurement._residuals import ResidualBlock, Weights
from kinecal.models import CalibrationModel
from kinecal.typing import Float

__all__ = ["FoldStep", "Score", "every_row", "run_folds"]

# training and held-out metrics and the fold's solution
Score = tuple[Metrics, Metrics, Float] | ValueError


def run_folds(
    fit: CandidateFit, test: list[np.ndarray], always_train: np.ndarray, unit: str
) -> list[Score]:
    """The training and held-out metrics of the candidate in every fold, and its
    solution there (a ``ValueError`` for a fold whose training rows cannot determine
    it; a held-out set scored by
    :func:`~kinecal.identification.selection._crossval.held_out_metrics`)."""
    problem, cm = fit.problem()
    meas, shared = fit.meas, fit.shared
    lm = warm_options(shared.lm)
    prior = Prior(fit.prior_mean, fit.prior_sigma)
    held = np.asarray([s.group in ("base", "cam") for s in cm.layout.specs])
    labels = [s.label for s in cm.layout.specs]
    whole, w_all = every_row(problem, cm, fit)
    step = FoldStep.at(problem, cm, fit, prior, whole, w_all)
    scores: list[Score] = []
    for t in test:
        mask = np.zeros(meas.n, bool)
        mask[t] = True
        mask &= ~always_train
        train = shared.keep & ~mask
        # Frames of sets and markers without a training row are held.
        present = {meas.set_labels[i] for i in used(meas.set_index[train])}
        present |= {meas.marker_labels[i] for i in used(meas.marker_index[train])}
        free = fit.free & ~(held & np.array([lb not in present for lb in labels]))
        c, n_train = meas.components, int(train.sum())
        if n_train * c <= cm.size:  # as a calibration on these rows would refuse
            scores.append(
                IdentifiabilityError(
                    f"{meas.source}: {n_train} training poses give {n_train * c} "
                    f"residuals, but the '{fit.spec.name}' model has {cm.size} "
                    "parameters."
                )
            )
            continue

        def training(train: np.ndarray = train) -> tuple[Problem, State]:
            """The problem and start on the training rows (made only when needed: the
            LM, or a second Newton step)."""
            state = problem.start(train).but(
                model=cm, x=fit.x, weights=shared.weights(train)
            )
            return problem.on(state), state

        x, x0, every = step.fold(training, mask, free) if step else (None, None, None)
        if x is None:  # the LM, lifted, from the step (or from the candidate's fit)
            view, state = training()
            _, res = run_lm(
                view,
                state,
                "auto: fold",
                fit.x if x0 is None else x0,
                free,
                lm,
                active_prior(prior, free),
                required=False,
                lifted=True,
            )
            x = res.x
        if every is None:  # every row at the fold's solution: both sides' errors
            every = whole.evaluations(cm, x, w_all)
        e_p, e_r = every.raw_position, every.raw_rotation
        trained = metrics_from_errors(e_p[train], None if e_r is None else e_r[train])
        if unit == "set":  # a held-out set: its user frame refitted first
            status = ["estimated" if f else "unidentifiable" for f in fit.free]
            cal = CalibratedModel(
                cm, x, np.full(cm.size, np.nan), status, problem.reference_payload_kg
            )
            held_out = held_out_metrics(cal, relabel_sets(meas.subset(mask)), unit)
        else:
            held_out = metrics_from_errors(
                e_p[mask], None if e_r is None else e_r[mask]
            )
        scores.append((trained, held_out, x))
    return scores


def every_row(
    problem: Problem, cm: CalibrationModel, fit: CandidateFit
) -> tuple[Problem, Weights]:
    """The candidate's problem on every row, the rejected ones too (a held-out set has
    them), and its weights (1 on the rejected rows, whose whitened residuals are not
    used): one evaluation there at a fold's solution gives the training cost and both
    sides' errors."""
    shared = fit.shared
    w_all = Weights(
        np.where(shared.keep, shared.sigma, 1.0),
        None
        if shared.sigma_rot is None
        else np.where(shared.keep, shared.sigma_rot, 1.0),
    )
    every = np.ones(fit.meas.n, bool)
    state = problem.start(every).but(model=cm, x=fit.x, weights=w_all)
    return problem.on(state), w_all


class FoldStep:
    """A fold's fit as a Newton step from the candidate's fit on every kept row, with
    the Jacobian there (Eq. (T-10), docs/theory.md): the training rows' normal
    equations are those of every row less the held-out rows', the gradient is minus the
    held-out rows', and the link pairs add their exact second-order terms. The step is
    kept when the training cost falls as its quadratic model predicts; otherwise up to
    :data:`_NEWTON_STEPS` in all, then the fold's LM."""

    def __init__(
        self,
        cm: CalibrationModel,
        fit: CandidateFit,
        prior: Prior,
        J: Float,
        r: Float,
        keep: np.ndarray,
        whole: Problem,
        w_all: Weights,
    ) -> None:
        P = cm.size
        self.cm, self.x, self.prior = cm, fit.x, prior
        self.keep, self.whole, self.w_all = keep, whole, w_all
        self.cols = np.flatnonzero(fit.free)
        self.s = cm.layout.scales[self.cols]
        # Parameter-major (k, c, N) as the model gives them: products over all rows
        # without a copy, and the held-out rows gathered contiguously (np.take).
        Jt = J.transpose(2, 1, 0)  # (P', c, N)
        self.Jt = Jt[self.cols] * self.s[:, None, None]
        self.rt = np.ascontiguousarray(r.T)  # (c, N)
        # The link terms are bilinear (lambda*_j s_k, Eq. 24-26): the cost's exact
        # Hessian adds, for each free pair, sum(r * d2r / dlambda ds), and d2r / dlambda
        # ds is the pair's product column (to first order in the deflection).
        at = {int(c_): i for i, c_ in enumerate(self.cols)}
        pairs = [
            (k, at[a], at[b])
            for k, (a, b) in enumerate(cm.link_products)
            if a in at and b in at
        ]
        self.pairs = np.array([(i, j) for _, i, j in pairs], np.intp).reshape(-1, 2)
        self.pair_index = np.array([k for k, _, _ in pairs], np.intp)
        self.Jpt = Jt[P + self.pair_index]
        self.pair_scale = self.s[self.pairs[:, 0]] * self.s[self.pairs[:, 1]]
        self.r = r
        self.A, self.g = _normal(self.Jt, self.rt)
        self.t = _flat(self.Jpt) @ self.rt.ravel() * self.pair_scale
        self.P = prior.precision[self.cols] * self.s**2
        self.pos = np.full(keep.size, -1)
        self.pos[keep] = np.arange(int(keep.sum()))

    @classmethod
    def at(
        cls,
        problem: Problem,
        cm: CalibrationModel,
        fit: CandidateFit,
        prior: Prior,
        whole: Problem,
        w_all: Weights,
    ) -> FoldStep | None:
        """The step's factors at the candidate's fit (None for a robust loss, or large
        data whose Jacobian is not held: the folds take the LM). ``whole``: the problem
        on every row with weights ``w_all``, where a step is checked."""
        if fit.shared.lm.loss != "linear":
            return None
        keep = fit.shared.keep
        state = problem.start(keep).but(model=cm, x=fit.x, weights=fit.weights())
        # (the fit's own evaluations: the Jacobian at its solution, when kept there)
        blk = problem.on(state).evaluations(
            cm, fit.x, state.weights, jacobian=True, products=True
        )
        if blk.J is None:
            return None
        return cls(cm, fit, prior, blk.J, blk.r, keep, whole, w_all)

    def fold(
        self,
        training: Callable[[], tuple[Problem, State]],
        held_out: np.ndarray,
        free: np.ndarray,
    ) -> tuple[Float | None, Float | None, ResidualBlock | None]:
        """``(x, None, every)``: the fold's solution and every row's residuals there;
        ``(None, x0, None)``: Newton did not settle, the LM goes on from ``x0`` (None:
        from the candidate's fit). ``training()``: the problem on the training rows."""
        rows = self.pos[held_out & (self.pos >= 0)]
        train = np.ones(self.r.shape[0], bool)
        train[rows] = False
        train_all = self.keep & ~held_out  # the same rows, among every row
        use = free[self.cols]
        # The training rows' Hessian and gradient: every row's less the held-out ones'.
        rh = np.take(self.rt, rows, axis=1)
        A_h, g_h = _normal(np.take(self.Jt, rows, axis=2), rh)
        H, g = self.A - A_h, self.g - g_h
        if self.pairs.size:
            t_h = _flat(np.take(self.Jpt, rows, axis=2)) @ rh.ravel()
            t = self.t - t_h * self.pair_scale
            H[self.pairs[:, 0], self.pairs[:, 1]] += t
            H[self.pairs[:, 1], self.pairs[:, 0]] += t
        x = self.x
        cost = 0.5 * float(np.sum(self.r[train] ** 2)) + self.prior.cost(x)
        for it in range(_NEWTON_STEPS):
            if it:  # Hessian and gradient at the new point, on the training rows
                view, state = training()
                blk = view.evaluations(
                    self.cm, x, state.weights, jacobian=True, products=True
                )
                if blk.J is None:
                    return None, x, None
                H, g = self._hessian(blk.J, blk.r)
            A = H[np.ix_(use, use)]
            A[np.diag_indices_from(A)] += self.P[use]
            gu = g[use] + self._prior_gradient(x)[use]
            d = -spd_solve(A, gu, rcond=1e-14)  # Eq. (T-10)
            if not np.all(np.isfinite(d)):
                return None, x if it else None, None
            predicted = -(gu @ d + 0.5 * d @ A @ d)
            if it and predicted <= _STEP_SLACK:  # converged at x, which a step reached
                return x, None, self.whole.evaluations(self.cm, x, self.w_all)
            x1 = x.copy()
            x1[self.cols[use]] += d * self.s[use]
            every = self.whole.evaluations(self.cm, x1, self.w_all)
            cost1 = 0.5 * float(np.sum(every.r[train_all] ** 2)) + self.prior.cost(x1)
            as_predicted = (
                abs((cost - cost1) - predicted) <= 0.1 * abs(predicted) + _STEP_SLACK
            )
            if as_predicted:  # the quadratic model holds: x1 is its optimum
                return x1, None, every
            if cost1 >= cost:  # too long a step along a weakly determined direction
                damped = self._damped(A, gu, use, x, cost, train_all)
                if damped is None:
                    return None, x if it else None, None
                x1, cost1 = damped
            x, cost = x1, cost1
        return None, x, None

    def _damped(
        self,
        A: Float,
        g: Float,
        use: np.ndarray,
        x: Float,
        cost: float,
        train_all: np.ndarray,
    ) -> tuple[Float, float] | None:
        """A Levenberg-Marquardt step on the same normal equations (damping 1e-3 to 10
        of their diagonal): the point and its cost, or None when none lowers the cost.
        A fold whose full step overshoots (3 of 40 on 2000 twin poses) then goes on with
        Newton steps instead of a whole LM run."""
        diag = np.diag(A).copy()
        for mu in (1e-3, 1e-2, 1e-1, 1.0, 10.0):
            d = -spd_solve(A + mu * np.diag(diag), g, rcond=1e-14)
            if not np.all(np.isfinite(d)):
                return None
            x1 = x.copy()
            x1[self.cols[use]] += d * self.s[use]
            r1 = self.whole.evaluations(self.cm, x1, self.w_all).r[train_all]
            cost1 = 0.5 * float(np.sum(r1**2)) + self.prior.cost(x1)
            if cost1 < cost:
                return x1, cost1
        return None

    def _hessian(self, J: Float, r: Float) -> tuple[Float, Float]:
        """Gauss-Newton Hessian with the link pairs' exact terms, and the gradient, of
        the data rows ``J``, ``r`` (scaled coordinates)."""
        Jt = J.transpose(2, 1, 0)  # (P', c, N)
        rt = np.ascontiguousarray(r.T)
        H, g = _normal(Jt[self.cols] * self.s[:, None, None], rt)
        if self.pairs.size:
            t = _flat(Jt[self.cm.size + self.pair_index]) @ rt.ravel()
            t *= self.pair_scale
            H[self.pairs[:, 0], self.pairs[:, 1]] += t
            H[self.pairs[:, 1], self.pairs[:, 0]] += t
        return H, g

    def _prior_gradient(self, x: Float) -> Float:
        """The prior's gradient at ``x`` over the free columns (scaled coordinates)."""
        c = self.cols
        dev = np.where(np.isfinite(self.prior.sigma[c]), x[c] - self.prior.mean[c], 0.0)
        return dev * self.prior.precision[c] * self.s


def _flat(Jt: Float) -> Float:
    """A parameter-major Jacobian (k, c, N) as (k, c N) (no copy when contiguous)."""
    return Jt.reshape(Jt.shape[0], Jt.shape[1] * Jt.shape[2])


def _normal(Jt: Float, rt: Float) -> tuple[Float, Float]:
    """``Jᵀ J`` and ``Jᵀ r`` of a parameter-major Jacobian (k, c, N) and residuals
    (c, N) (BLAS)."""
    f = _flat(Jt)
    return f @ f.T, f @ rt.ravel()


# Newton steps a fold may take before the LM takes over.
_NEWTON_STEPS = 3

# The cost [chi^2 / 2] a Newton step may miss its quadratic model by, and the decrease
# below which a fold's fit has converged (the statistical resolution of a parameter is
# 1/2).
_STEP_SLACK = 0.5
