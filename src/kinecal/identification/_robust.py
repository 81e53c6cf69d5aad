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

import math
from dataclasses import dataclass, replace

import numpy as np

from kinecal._stats import present, quantiles
from kinecal.identification._options import MU0_WARM
from kinecal.identification._press import loo_position_errors, rms_mm
from kinecal.identification._problem import Problem, Stage, State, run_stages
from kinecal.identification._solve import run_lm
from kinecal.identification._stages import robust_sigma, run_shared
from kinecal.measurement._diagnostics import Diagnostic, Outlier
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import Weights, residuals
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.typing import Float

__all__ = [
    "RobustRejection",
    "Structure",
    "chi2_isf",
    "find_outliers",
    "residual_structure",
    "row_z",
]

_MAX_ROUNDS = 6
# Suspects left out of the test fit are at most this fraction of the rows.
_MAX_SUSPECT = 0.3
# A candidate must exceed this multiple of the largest z of the rows within the quantile.
# On the shipped FR3 camera data (heavy-tailed, informative far rows) the farthest rows of
# the 5-fold training sets reach 2.8 times; gross errors on the twin, hundreds of times.
_GAP = 4.0
# Residual structure: a rank correlation this strong with one pose variable, with the
# candidates gathered in that variable's upper (or lower) third, is systematic.
_RHO_SYSTEMATIC = 0.5
_GATHERED = 2.0 / 3.0


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
    blk = residuals(
        state.model, state.x, meas, Weights.default(meas), inputs=root.inputs
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


@dataclass(frozen=True)
class Structure:
    """How the largest residuals follow the pose (:func:`residual_structure`)."""

    variable: str  # e.g. "J2's gravity load"
    joint: int
    systematic: bool
    rho: float = 0.0  # rank correlation of the errors with the variable
    rms_now_mm: float = float("nan")  # with a compliance model: RMS now ...
    rms_after_mm: float = float("nan")  # ... and after its linearised fit


def _ranks(v: Float) -> Float:
    order = np.argsort(v, kind="stable")
    r = np.empty(v.size)
    r[order] = np.arange(v.size, dtype=float)
    return r


def _spearman(a: Float, B: Float) -> Float:
    """Spearman correlation of ``a`` (N,) with every column of ``B`` (N, k)."""
    ra = _ranks(a)
    ra = (ra - ra.mean()) / max(ra.std(), 1e-300)
    RB = np.column_stack([_ranks(b) for b in B.T])
    RB = (RB - RB.mean(axis=0)) / np.maximum(RB.std(axis=0), 1e-300)
    return (ra @ RB) / a.size


def _full_spec(model: CalibrationModel) -> ModelSpec:
    """The model with every compliance term (the terms the pose may reveal)."""
    spec = model.spec
    full = ModelSpec.preset(
        "full",
        cam_rotation=spec.cam_rotation,
        sets=spec.sets,
        markers=spec.markers,
        hayati=spec.hayati,
        ntm_joints=spec.ntm_joints or model.robot.ntm_joints,
        has_self_weight=model.robot.self_weight is not None,
        link_bodies=model.robot.link_bodies,
    )
    return full


def _lacks_terms(model: CalibrationModel) -> bool:
    """Whether the full model has terms this one lacks."""
    full = _full_spec(model)
    return not set(CalibrationModel(model.robot, full).layout.names) <= set(
        model.layout.names
    )


_SAMPLE = (
    5000  # rows the structure test looks at, at most (every k-th, plus the flagged)
)


def _sample(n: int, flagged: np.ndarray) -> np.ndarray:
    """Indices of at most about :data:`_SAMPLE` rows, evenly spread, and every flagged."""
    step = max(1, n // _SAMPLE)
    keep = np.zeros(n, bool)
    keep[::step] = True
    return np.flatnonzero(keep | flagged)


@dataclass(frozen=True)
class _Score:
    """A linearised fit of the full model's extra terms on some rows."""

    rows: np.ndarray
    err: Float  # (n,) position error norms now [m]
    err_after: Float  # (n,) after the fit [m]
    now_mm: float  # RMS now, corrected for the parameters fitted [mm]
    after_mm: float  # RMS after [mm]
    joint: int  # the joint whose terms explain the most
    kind: str  # 'load' or 'ntm': the term that explains most


def compliance_score(
    problem: Problem, state: State, rows: np.ndarray, fit: np.ndarray
) -> _Score:
    """What the full model's extra terms (transmission, payload and link compliance, in
    the lifted coordinates of Eq. (T-2)) explain of the position errors of ``rows``: a
    linearised least-squares fit of them with the present parameters on the rows ``fit``
    (bool over ``rows``), applied to all of them (so rows left out of it are predicted,
    not absorbed)."""
    full, xf = _transferred(state.model, state.x)
    meas = problem.meas.subset(rows)
    w = Weights(np.ones(meas.n), None if meas.kind != "pose" else np.ones(meas.n))
    blk = residuals(
        full,
        xf,
        meas,
        w,
        inputs=problem.inputs.subset(rows),
        jacobian=True,
        products=True,
        hold=True,
    )
    assert blk.J is not None
    names = full.layout.names
    own = set(state.model.layout.names)  # (np.isin of strings imports numpy.ma)
    present = np.array([n in own for n in names], bool)
    groups = [sp.group for sp in full.layout.specs]
    extra = ~present & np.array([g in ("ntm", "load") for g in groups], bool)
    specs = full.layout.specs
    col_joint = [sp.joint or 0 for sp in specs] + [
        specs[a].joint or 0 for a, _ in full.link_products
    ]
    col_kind = list(groups) + ["load"] * len(full.link_products)
    cols = np.concatenate([present | extra, np.ones(len(full.link_products), bool)])
    idx = np.flatnonzero(cols)
    A = blk.J[:, :3, idx]  # (n, 3, k)
    e = blk.raw_position
    delta, *_ = np.linalg.lstsq(
        A[fit].reshape(-1, idx.size), -e[fit].reshape(-1), rcond=None
    )
    rest = e + A @ delta
    # The part each joint's new terms explain (their columns' share of the correction).
    new_cols = [k for k, i in enumerate(idx) if i >= full.size or extra[i]]
    share: dict[tuple[int, str], float] = {}
    for k in new_cols:
        key = (col_joint[idx[k]], str(col_kind[idx[k]]))
        share[key] = share.get(key, 0.0) + float(np.sum((A[:, :, k] * delta[k]) ** 2))
    joint, kind = max(share, key=lambda kk: share[kk]) if share else (0, "load")
    m = e[fit].size
    k_now = int(np.sum(state.free))
    k_full = k_now + len(new_cols)
    now = float(np.sqrt(np.sum(e[fit] ** 2) / max(m - k_now, 1) * 3.0)) * 1e3
    after = float(np.sqrt(np.sum(rest[fit] ** 2) / max(m - k_full, 1) * 3.0)) * 1e3
    return _Score(
        rows,
        np.linalg.norm(e, axis=1),
        np.linalg.norm(rest, axis=1),
        now,
        after,
        joint,
        kind,
    )


def _transferred(model: CalibrationModel, x: Float) -> tuple[CalibrationModel, Float]:
    """The full model at the parameters of ``model`` (extra terms zero)."""
    full = model.with_spec(_full_spec(model))
    return full, full.layout.transfer(x, model.layout)


def pose_variables(
    problem: Problem, state: State, rows: np.ndarray
) -> tuple[Float, list[str], list[int]]:
    """Pose variables of ``rows`` the residuals may follow: each joint's angle and the
    deflection a unit compliance of that joint would cause under the tool's weight
    (``‖∂p/∂λ*_j‖``, which grows with the joint's gravity load)."""
    meas = problem.meas
    load = _load_columns(problem, state, rows)  # (n_rows, n)
    n = meas.n_joints
    names = [f"J{j + 1}" for j in range(n)] + [
        f"J{j + 1}'s gravity load" for j in range(n)
    ]
    joints = list(range(1, n + 1)) * 2
    return np.column_stack([meas.q_ctrl[rows], load]), names, joints


def _load_columns(problem: Problem, state: State, rows: np.ndarray) -> Float:
    """``‖∂p/∂λ*_j‖`` at the rows ``rows`` for every joint j: from the Jacobian kept at
    the state's solution when the model is the full one (the uncertainty's: no new
    pass, issue 36), else from the full model there."""
    cm = state.model
    kept = problem.evaluations.kept(cm, state.x, state.weights)
    if (
        kept is not None
        and kept.J is not None
        and replace(_full_spec(cm), name=cm.spec.name)
        == replace(cm.spec, ntm_joints=cm.spec.ntm_joints or cm.robot.ntm_joints)
    ):
        lam = cm.layout.group_indices("load")
        sigma = state.weights.sigma[rows]
        J_p = kept.J[rows][:, :3][:, :, lam] * sigma[:, None, None]  # unwhitened
        return np.asarray(np.linalg.norm(J_p, axis=1), np.float64)
    full, xf = _transferred(cm, state.x)
    out = full.evaluate(xf, problem.inputs.subset(rows), jacobian=True)
    assert out.J_p is not None
    lam = full.layout.group_indices("load")
    return np.asarray(np.linalg.norm(out.J_p[:, :, lam], axis=1), np.float64)


def residual_structure(
    problem: Problem, state: State, err: Float, flagged: np.ndarray
) -> Structure | None:
    """Whether the errors (``err``, rows of ``problem``) follow the pose.

    A model without every compliance term: systematic when a linearised fit of the full
    model's extra terms on the rows not ``flagged`` (:func:`compliance_score`) halves
    their error variance and, if rows are flagged, predicts at least two thirds of them
    to within half their error. A model
    with every term: systematic when the errors' rank correlation with a joint angle or
    gravity load reaches 0.5 and two thirds of the flagged rows lie in that variable's
    upper (or lower) third. None for fewer than 10 rows. Large data are sampled.
    """
    if err.size < 10:
        return None
    rows = _sample(err.size, flagged)
    f = flagged[rows]
    if _lacks_terms(state.model):
        sc = compliance_score(problem, state, rows, ~f)
        explained = sc.after_mm**2 < 0.5 * sc.now_mm**2
        follow = (
            float(np.mean(sc.err_after[f] < 0.5 * sc.err[f])) >= _GATHERED
            if f.any()
            else True
        )
        what = (
            f"J{sc.joint}'s gravity load"
            if sc.kind == "load"
            else f"J{sc.joint}'s angle (its transmission error)"
        )
        return Structure(
            what,
            sc.joint,
            explained and follow,
            rms_now_mm=sc.now_mm,
            rms_after_mm=sc.after_mm,
        )
    V, names, joints = pose_variables(problem, state, rows)
    rho = _spearman(err[rows], V)
    rho = np.where(np.ptp(V, axis=0) > 0, rho, 0.0)
    k = int(np.argmax(np.abs(rho)))
    gathered = 1.0
    if f.any():
        v = V[:, k]
        lo, hi = quantiles(v, [1.0 / 3.0, 2.0 / 3.0])
        gathered = max(float(np.mean(v[f] >= hi)), float(np.mean(v[f] <= lo)))
    systematic = abs(rho[k]) >= _RHO_SYSTEMATIC and gathered >= _GATHERED
    return Structure(names[k], joints[k], systematic, rho=float(rho[k]))


def systematic_diagnostic(
    problem: Problem, state: State, st: Structure, stage: str
) -> Diagnostic:
    """``systematic_residuals``: what the residuals follow, and what would explain it."""
    if np.isfinite(st.rms_after_mm):
        share = 1.0 - (st.rms_after_mm / st.rms_now_mm) ** 2
        text = (
            f"the largest residuals follow {st.variable}: a joint compliance model "
            f"explains {share:.1%} of their variance (with --model full the RMS error "
            f"of these poses would fall from {st.rms_now_mm:.4g} to about "
            f"{st.rms_after_mm:.4g} mm, by a linearised fit of its extra terms). They "
            "are systematic, not gross errors: no row is rejected, and a robust loss "
            "would not help."
        )
    else:
        text = (
            f"the largest residuals follow {st.variable} (rank correlation "
            f"{st.rho:+.2f} of the errors with it): they are systematic, not gross "
            "errors, so no row is rejected and a robust loss would not help. The model "
            f"misses an effect that grows with {st.variable}: check the payload "
            "(payload_kg), the robot's self-weight data, or more transmission harmonics "
            "(--ntm-order)."
        )
    return Diagnostic(
        "systematic_residuals",
        text,
        parameters=(),
        stage=stage,
    )


@dataclass(frozen=True)
class RobustRejection:
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

    def __call__(self, problem: Problem, state: State) -> State:
        opts = problem.options
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
        rob_problem = root.with_options(
            replace(opts, loss=opts.loss if opts.loss != "linear" else "huber")
        )
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
    lm = replace(current.lm, max_iter=max(current.lm.max_iter, 200), mu0=MU0_WARM)
    state, res = run_lm(
        root.on(state),
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
