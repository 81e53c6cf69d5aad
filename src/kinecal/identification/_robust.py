"""Gross errors removed, not only reported; systematic residuals told apart from them.

A bumped reflector or a mistyped joint record moves a row far from the model; a model that
misses an effect (a heavy arm's J2 bending, fitted by a kinematic model) moves many rows a
little, smoothly with the pose. :class:`RobustRejection` removes the first and never the
second:

1. At the fit on the rows in use, every row's whitened error norm ``‖r_i‖`` is scaled by a
   robust noise estimate from the rows in use, ``σ̂ = median ‖r‖ / median(χ_c)``
   (Eq. (T-4)): ``z_i = ‖r_i‖ / σ̂``.
2. Candidates are rows beyond the chi quantile of probability ``outlier_p`` (or beyond
   ``reject_z``). A gross error stands apart from the noise: by default only candidates
   beyond four times the largest ``z`` of the rows within the quantile are rejected, so
   the heavy tail of real camera or mocap noise is kept (on the shipped FR3 camera data
   its far rows reach 2.8 times, and rejecting them raises the cross-validated error
   from 1.44 to 1.55-1.63 mm: they are informative).
3. Candidates whose errors follow the pose (:func:`residual_structure`: their error
   grows with a joint angle or a joint's gravity load) are systematic: none is rejected.
4. Otherwise the fit is repeated without the rejected rows (every stage: registration,
   priors and their widening are computed on the cleaned data). The suspects come from a
   fit with a Huber loss on all rows; the test is made at the accepted fit refitted
   without them, from its own solution (a few Levenberg-Marquardt steps).
5. The new fit is kept only if it predicts the rows both fits use better (leave-one-out
   position errors, Eq. (T-5)): a gross error pulls the fit and spoils the prediction of
   the others; a row that is far out but informative (a pose at the edge of the data on
   a robot the model fits imperfectly) does not. Then the test is repeated on all rows
   (a row may come back) until the rejected set no longer changes.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from kinecal._record import Record
from kinecal._stats import present
from kinecal.identification._options import RejectSettings
from kinecal.identification._problem import Problem, Stage, State, run_stages
from kinecal.identification._reweight import kept_errors, share_raw
from kinecal.identification._solve import run_lm, warm_options
from kinecal.identification._stages import robust_sigma, run_shared
from kinecal.identification._structure import (
    Structure,
    residual_structure,
    systematic_diagnostic,
)
from kinecal.measurement._diagnostics import Diagnostic, Outlier
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import ResidualBlock, Weights, residuals
from kinecal.typing import Float

__all__ = [
    "RobustRejection",
    "Structure",
    "chi2_isf",
    "find_outliers",
    "residual_structure",
    "row_z",
    "systematic_diagnostic",
]

_MAX_ROUNDS = 6
# Suspects left out of the test fit are at most this fraction of the rows.
_MAX_SUSPECT = 0.3
# A candidate must exceed this multiple of the largest z of the rows within the quantile.
# On the shipped FR3 camera data (heavy-tailed, informative far rows) the farthest rows of
# the 5-fold training sets reach 2.8 times; gross errors on the twin, hundreds of times.
_GAP = 4.0


def row_z(problem: Problem, state: State) -> tuple[Float, Float, Float]:
    """Robust ``z`` of every row of the data at the state's fit (Eq. (T-4)).

    Without sigmas in the data the rows are whitened by robust scales of their own, one
    per component kind (the median position and orientation errors of the rows in use),
    so gross errors do not hide behind a noise estimate they inflated.

    Returns
    -------
    z : (N,) whitened error norm over the robust noise of the rows in use.
    err_mm : (N,) 3-D position error [mm].
    r : (N, c) whitened residuals.
    """
    root = problem.root or problem
    meas = root.meas
    w = Weights.default(meas)
    # The fit's own errors where the root's cache keeps them (the probe's solution):
    # the same numbers as a pass (issue 36).
    blk = kept_errors(root.evaluations, state.model, state.x, w) or residuals(
        state.model, state.x, meas, w, inputs=root.inputs
    )
    active = state.active if state.active is not None else np.ones(meas.n, bool)
    r = blk.r
    if meas.sigma is None:
        parts = [blk.raw_position]
        if blk.raw_rotation is not None:
            parts.append(blk.raw_rotation)
        r = np.concatenate(
            [e / max(robust_sigma(e[active]), 1e-300) for e in parts], axis=1
        )
    sigma = robust_sigma(r[active])
    z = np.linalg.norm(r, axis=1) / max(sigma, 1e-300)
    return z, np.linalg.norm(blk.raw_position, axis=1) * 1e3, r


def gross(
    z: Float, active: np.ndarray, c: int, p: float, reject_z: float | None
) -> np.ndarray:
    """Rows to reject: beyond ``reject_z`` when given; otherwise beyond the chi quantile
    and beyond four times the largest z of the rows in use within it (they stand
    apart)."""
    if reject_z is not None:
        return z > reject_z
    t0 = math.sqrt(chi2_isf(c, p))
    bulk = z[active & (z <= t0)]
    cap = _GAP * float(bulk.max()) if bulk.size else t0
    return z > max(t0, cap)


@dataclass(frozen=True, eq=False, repr=False)
class RobustRejection(Record):
    """Reject gross errors and repeat the fit without them (module docstring).

    Attributes
    ----------
    fit : the stages repeated on the cleaned rows (registration to the evidence priors).
    probe : the stages of the robust fit on every row that finds the suspects
        (registration, identifiability and stage 1, run with a Huber loss).
    """

    fit: tuple[Stage, ...] = ()
    probe: tuple[Stage, ...] = ()
    name: str = "robust rejection"
    settings: RejectSettings | None = None  # None: from the problem's options

    def __call__(self, problem: Problem, state: State) -> State:
        opts = self.settings or RejectSettings.of(problem.options)
        if opts.reject == "off" or not self.fit:
            return state
        root = problem.root or problem
        meas = root.meas
        c, n = meas.components, meas.n
        t0 = math.sqrt(chi2_isf(c, opts.outlier_p))
        limit = opts.reject_z if opts.reject_z is not None else t0
        found: list[Diagnostic] = []
        current = state  # the accepted fit
        # Suspects: rows far from a robust fit of the kinematic model on every row (a
        # plain least-squares fit bends towards gross errors and hides them).
        loss = problem.options.loss
        rob_problem = root.with_options(
            replace(problem.options, loss=loss if loss != "linear" else "huber")
        )
        share_raw(root.evaluations, rob_problem.evaluations)  # its start: x_registered
        rob = run_shared(rob_problem, state, self.probe or self.fit)
        z, _, _ = row_z(rob_problem, rob)
        suspect = _largest(z > limit, z, _MAX_SUSPECT * n)
        for _ in range(_MAX_ROUNDS):
            in_use = current.active if current.active is not None else np.ones(n, bool)
            if not suspect.any():
                break
            # The test is made at a fit without every suspect (no gross error left to
            # pull it): rows far from it that stand apart are rejected, the others come
            # back.
            probe = _keep_enough(root, suspect)
            trimmed = _test_fit(root, current, ~probe)
            z, err, _ = row_z(root, trimmed)
            reject = _keep_enough(
                root, gross(z, ~probe, c, opts.outlier_p, opts.reject_z)
            )
            if not reject.any() or np.array_equal(~reject, in_use):
                break
            if 2 * int(reject.sum()) > n:
                found.append(_refused(meas, reject, self.name))
                break
            st = residual_structure(root, trimmed, err, reject)
            if st is not None and st.systematic:
                view = problem.on(current)
                found.append(systematic_diagnostic(view, current, st, self.name))
                break
            problem.progress(self.name, f"{int(reject.sum())} rows; fitting again")
            trial = run_stages(root, root.start(~reject), self.fit)
            if not _predicts_better(root, trial, current):
                break  # the rows carry information the others confirm: keep them
            current = trial
            # Confirm at the new fit: rows beyond the limit there (the rejected ones
            # and any the gross errors hid) are the next suspects.
            z, _, _ = row_z(root, current)
            suspect = _largest(z > limit, z, _MAX_SUSPECT * n) | reject
        if current.active is None or current.active.all():
            return current.note(*found)
        return _report(root, current, found, self.name)


def _test_fit(root: Problem, current: State, rows: np.ndarray) -> State:
    """The accepted fit refitted on ``rows`` (a mask over every row) from its own
    solution, with its priors and weights: the fit the test is made at. The fit that
    replaces the accepted one runs every stage on the cleaned rows (its priors and their
    widening from them); this one only has to leave the suspects out."""
    meas = root.meas
    use = current.active if current.active is not None else np.ones(meas.n, bool)
    sigma = Weights.default(meas)
    s, s_rot = sigma.sigma.copy(), sigma.sigma_rot
    s[use] = current.weights.sigma
    if s_rot is not None and current.weights.sigma_rot is not None:
        s_rot = s_rot.copy()
        s_rot[use] = current.weights.sigma_rot
    state = current.but(
        active=None if rows.all() else rows.copy(),
        weights=Weights(s, s_rot).subset(rows),
    )
    problem = root.on(state)
    if current.active is None and not rows.all():
        _start_held(root, problem, current, rows, state.weights)
    lm = warm_options(current.lm)
    state, res = run_lm(
        problem,
        state,
        "robust rejection: test fit",
        current.x,
        current.free,
        lm,
        current.active_prior(),
        required=False,
        lifted=True,
    )
    return state.but(x=res.x)


def _start_held(
    root: Problem, sub: Problem, current: State, rows: np.ndarray, w: Weights
) -> None:
    """The test fit's first evaluation from the accepted fit's, kept at its solution on
    every row (the last stage's, Jacobian with the product columns the lifted start
    reads): its rows ``rows``, in the layout of a new pass. Each pose is evaluated on
    its own and ``w`` holds the same sigmas, so these are the numbers a pass on the rows
    gives; the subset's cache serves them (issue 36: one forward and one Jacobian pass
    fewer where the probe found suspects)."""
    cm = current.model
    blk = root.evaluations.kept(cm, current.x, current.weights)
    if blk is None or blk.J is None:
        return
    idx = np.flatnonzero(rows)
    # J (N, c, P') is the transpose of a C-ordered (P', c, N) array: so is the new one.
    J = np.ascontiguousarray(blk.J.transpose(2, 1, 0)[:, :, idx]).transpose(2, 1, 0)
    rot = None if blk.raw_rotation is None else blk.raw_rotation[idx]
    part = ResidualBlock(blk.r[idx], J, blk.raw_position[idx], rot)
    sub.evaluations.put(cm, current.x, w, part)


def _largest(mask: np.ndarray, z: Float, most: float) -> np.ndarray:
    """``mask`` limited to its ``most`` rows of largest ``z``."""
    k = int(most)
    if mask.sum() <= k:
        return mask
    out = np.zeros_like(mask)
    idx = np.flatnonzero(mask)
    out[idx[np.argsort(-z[idx])[:k]]] = True
    return out


def _refused(meas: Measurements, rows: np.ndarray, stage: str) -> Diagnostic:
    return Diagnostic(
        "rejection_refused",
        f"{int(rows.sum())} of {meas.n} rows are far from the fit: more than half, so "
        "none is rejected (check the units, the robot file and the joint order).",
        rows=tuple(int(r) for r in meas.rows[rows]),
        stage=stage,
    )


def _predicts_better(root: Problem, trial: State, current: State) -> bool:
    """Whether the fit without the rejected rows predicts the rows both fits use better
    (leave-one-out position errors, Eq. (T-5)) than the fit with them: true for gross
    errors, which pull the fit; not for rows that are merely far out but informative."""
    n = root.meas.n
    a = trial.active if trial.active is not None else np.ones(n, bool)
    b = current.active if current.active is not None else np.ones(n, bool)
    both = a & b
    from kinecal.identification._press import loo_position_errors, rms_mm

    e_trial = loo_position_errors(root.on(trial), trial)[both[a]]
    e_current = loo_position_errors(root.on(current), current)[both[b]]
    return rms_mm(e_trial) < rms_mm(e_current)


def _report(root: Problem, state: State, found: list[Diagnostic], stage: str) -> State:
    """The rejected rows (their errors and z at the final fit) in the state and a
    ``rows_rejected`` diagnostic."""
    meas = root.meas
    assert state.active is not None
    z, err, _ = row_z(root, state)
    out = ~state.active
    order = np.flatnonzero(out)[np.argsort(-z[out])]
    rejected = tuple(
        Outlier(int(meas.rows[i]), float(err[i]), float(z[i])) for i in order
    )
    lines = ", ".join(
        f"{o.row} ({o.error_mm:.3g} mm, z {o.z:.3g})" for o in rejected[:10]
    )
    more = f" and {len(rejected) - 10} more" if len(rejected) > 10 else ""
    where = "file lines" if meas.source.endswith(".csv") else "rows"
    found.append(
        Diagnostic(
            "rows_rejected",
            f"{len(rejected)} rows rejected as gross errors (far beyond the noise of the "
            "others, standing apart from them, and the fit without them predicts the "
            f"others better) and the fit repeated without them: {where} {lines}{more}.",
            rows=tuple(o.row for o in rejected),
            stage=stage,
        )
    )
    return state.but(rejected=rejected).note(*found)


def _keep_enough(problem: Problem, reject: np.ndarray) -> np.ndarray:
    """Rejection never empties a set or marker below 3 rows (its frame needs them)."""
    meas = problem.meas
    out = reject.copy()
    for idx in (meas.set_index, meas.marker_index):
        for g in present(idx):
            rows = idx == g
            if np.sum(rows & ~out) < 3:
                out[rows] = False
    return out


@functools.lru_cache(maxsize=64)
def chi2_isf(df: int, p: float) -> float:
    """Chi-square quantile with ``P(X > x) = p`` for an integer number of degrees of freedom.

    The survival function has a closed form for integer ``df`` (a Poisson sum for even
    ``df``, erfc plus a half-integer sum for odd); bisection inverts it to round-off.
    Written out so calibration does not import scipy.special (0.2 s at start-up);
    remembered per arguments (a calibration asks for the same quantile several times).
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
    """Rows whose whitened error norm is improbable (chi quantile of probability ``p``)
    under the noise of the other rows, most improbable first.

    The suspects are found with the robust noise ``median ‖r‖ / median(χ_c)`` (Eq. (T-4));
    the test then uses the noise of the rows that are not suspect,
    ``sqrt(Σ ‖r‖² / (c n))`` over them, so the suspects do not inflate it.
    """
    c = r.shape[1]
    norms = np.linalg.norm(r, axis=1)
    sigma = robust_sigma(r)
    if sigma <= 0:
        return []
    thr = math.sqrt(chi2_isf(c, p))  # chi-square quantile: P(X > thr^2) = p
    suspect = norms / sigma > thr
    rest = norms[~suspect]
    if rest.size:
        sigma = float(np.sqrt(np.sum(rest**2) / (c * rest.size)))
    z = norms / max(sigma, 1e-300)  # Eq. (T-4)
    bad = np.flatnonzero(z > thr)
    err = np.linalg.norm(e_pos, axis=1) * 1e3
    order = bad[np.argsort(-z[bad])]
    return [Outlier(int(meas.rows[i]), float(err[i]), float(z[i])) for i in order]
