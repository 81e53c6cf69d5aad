"""Whether the largest residuals follow the pose: systematic errors, not gross ones
(:class:`~kinecal.identification.RobustRejection`, :class:`Diagnose`).

A model that misses an effect (a heavy arm's J2 bending, fitted by a kinematic model)
moves many rows a little, smoothly with the pose: :func:`residual_structure` tells such
residuals apart from gross errors, by what the full model's extra terms would explain
of them (a model without every term) or by their rank correlation with a joint angle or
gravity load (a model with every term).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal._record import Record
from kinecal._stats import quantiles
from kinecal.identification._problem import Problem, State
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._residuals import Weights, residuals
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.typing import Float

__all__ = [
    "Structure",
    "compliance_score",
    "pose_variables",
    "residual_structure",
    "systematic_diagnostic",
]

# Residual structure: a rank correlation this strong with one pose variable, with the
# candidates gathered in that variable's upper (or lower) third, is systematic.
_RHO_SYSTEMATIC = 0.5
_GATHERED = 2.0 / 3.0


@dataclass(frozen=True, eq=False, repr=False)
class Structure(Record):
    """How the largest residuals follow the pose (:func:`residual_structure`)."""

    variable: str  # e.g. "J2's gravity load"
    joint: int
    systematic: bool
    rho: float = 0.0  # rank correlation of the errors with the variable
    rms_now_mm: float = float("nan")  # with a compliance model: RMS now ...
    rms_after_mm: float = float("nan")  # ... and after its linearised fit


def _ranks(v: Float) -> Float:
    """The rank of every value of ``v`` along its first axis (ties by position)."""
    order = np.argsort(v, axis=0, kind="stable")
    r = np.empty(v.shape)
    place = np.arange(v.shape[0], dtype=float).reshape(-1, *[1] * (v.ndim - 1))
    np.put_along_axis(r, order, np.broadcast_to(place, v.shape), axis=0)
    return r


def _spearman(a: Float, B: Float) -> Float:
    """Spearman correlation of ``a`` (N,) with every column of ``B`` (N, k)."""
    ra = _ranks(a)
    ra = (ra - ra.mean()) / max(ra.std(), 1e-300)
    RB = _ranks(B)  # every column's ranks at once (one stable sort: the same ranks)
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
    if full == model.spec:  # the full model itself (no second build of its layout)
        return False
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


@dataclass(frozen=True, eq=False, repr=False)
class _Score(Record):
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
        # The load columns of the position rows first, then the rows: the same
        # numbers without a copy of the whole Jacobian (issue 36).
        J_p = kept.J[:, :3, lam][rows] * sigma[:, None, None]  # unwhitened
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
