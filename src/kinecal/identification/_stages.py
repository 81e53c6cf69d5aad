"""The stages of a calibration (paper Sec. 4, Fig. 6), each ``(problem, state) -> state``.

0. :class:`Register`: closed-form user and cam frames from nominal kinematics, refined by
   LM: the "before calibration" state.
1. :class:`Identify`: the parameters the poses determine (the rest are held).
2. :class:`~kinecal.identification._priors.Priors`: Gaussian priors with physical scales,
   the geometry ones adapted to the data.
3. :class:`KinematicStage` (paper stage 1): the unified kinematic parameters.
4. :class:`TransmissionStage` (paper stage 2): the Fourier coefficients by linear least
   squares, directly on the position residuals or by the paper's projection (Eq. 29).
5. :class:`FullStage` (paper stage 3): every parameter together, from stages 1-2.
6. :class:`~kinecal.identification._priors.EvidencePriors`: transmission and compliance
   prior scales by maximum evidence, stage 3 again when they change.
7. :class:`~kinecal.identification._robust.RobustRejection`: gross errors out, the fit
   again on the clean rows.
8. :class:`~kinecal.identification._uncertainty.Uncertainty` and
   :class:`~kinecal.identification._diagnose.Diagnose`.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from kinecal._record import Record
from kinecal._stats import median
from kinecal.errors import IdentifiabilityError
from kinecal.identification._frame_fit import FrameFit
from kinecal.identification._identifiability import (
    identifiability_from_normal,
)
from kinecal.identification._lm import LMOptions, spd_solve
from kinecal.identification._noise import estimate_noise
from kinecal.identification._normal import block_normal
from kinecal.identification._options import (
    MU0_WARM,
    STOL,
    STOL_PRE,
    FitSettings,
    IdentifySettings,
)
from kinecal.identification._problem import Problem, Stage, State, run_stages
from kinecal.identification._registration import initial_registration
from kinecal.identification._solve import run_lm
from kinecal.measurement._diagnostics import Diagnostic, StageLog
from kinecal.measurement._residuals import Weights, residuals
from kinecal.models import CalibrationModel, ntm_basis
from kinecal.typing import Float

__all__ = [
    "FullStage",
    "Identify",
    "KinematicStage",
    "Register",
    "TransmissionStage",
    "robust_sigma",
    "run_shared",
]

# Stage 3 re-estimates the noise and refits until no sigma moves by more than 20 %
# (at most this many times).
_NOISE_ROUNDS = 3
_NOISE_TOL = 1.2
# Median of the chi distribution with c degrees of freedom (norm of a c-D unit Gaussian).
_CHI_MEDIAN = {3: 1.5381722, 6: 2.3660319}


def robust_sigma(r: Float) -> float:
    """Noise per component from the median row norm (whitened units)."""
    c = r.shape[1]
    med = median(np.linalg.norm(r, axis=1))
    return med / _CHI_MEDIAN.get(c, np.sqrt(c - 0.5))


@dataclass(frozen=True, eq=False, repr=False)
class Register(Record):
    """User and cam frames from nominal kinematics (:mod:`._registration`), then LM on
    them; for pose data without sigmas, the position and orientation noise from its
    residuals and the LM once more with those weights."""

    name: str = "registration"

    def __call__(self, problem: Problem, state: State) -> State:
        problem.progress("init", "closed-form user and cam frames")
        # While the frames alone move, the model's points follow from the flange
        # frames: one forward pass for the closed form and the fit (issue 36; None
        # where that does not hold: by the model).
        fit = FrameFit.of(state.model, state.x, problem.meas, problem.inputs)
        model, x, found = initial_registration(
            state.model,
            state.x,
            problem.meas,
            inputs=problem.inputs,
            flange=None if fit is None else fit.flange,
        )
        # In a calibration the identifiability analysis decides (and reports) what the
        # poses leave undetermined: the closed form's finding is only a note.
        state = state.but(model=model).note(
            *(replace(d, severity="info") for d in found)
        )
        frames = problem.frames
        # The closed form is next to the optimum: little initial damping (MU0_WARM).
        warm = replace(state.lm, mu0=MU0_WARM)
        fit = None if fit is None else fit.on(model)  # its reference rotations
        # A pre-fit: every later stage fits the frames again (a registration that
        # stopped drifting along a direction the nominal robot leaves open, a sensor's
        # cam.r, failed a calibration whose stages all converged after it).
        state, res = run_lm(
            problem, state, self.name, x, frames, warm, evaluate=fit, required=False
        )
        x = res.x
        if problem.meas.kind == "pose" and problem.estimate_noise:
            state = estimate_noise(problem, state, x, frames, None)
            again = f"{self.name} (noise weights)"  # with the weights just estimated
            state, res = run_lm(problem, state, again, x, frames, warm, evaluate=fit)
            x = res.x
        if fit is not None:  # the model's own Jacobian where the next stage starts
            # (with the product columns: stage 3 may lift from stage 1's solution)
            products = bool(model.link_products)
            problem.evaluations(
                model, x, state.weights, jacobian=True, products=products
            )
        return state.but(x=x, x_registered=x)


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


@dataclass(frozen=True, eq=False, repr=False)
class Identify(Record):
    """The identifiability analysis (:func:`analyse_identifiability`) at a generic point:
    parameters the poses cannot determine are held at their start values.

    Diagnostics: ``targets_few`` (sensor sets seeing fewer than three targets, or all on
    one line), ``frames_undetermined`` (user and tool frame parameters that trade off).

    Raises
    ------
    IdentifiabilityError
        Fewer residuals than identifiable parameters.
    """

    name: str = "identifiability"
    settings: IdentifySettings | None = None  # None: from the problem's options

    def __call__(self, problem: Problem, state: State) -> State:
        problem.progress("identifiability", "scaled Jacobian")
        cm, meas = state.model, problem.meas
        opts = self.settings or IdentifySettings.of(problem.options)
        g = _generic_point(cm, state.x)
        A = _generic_normal(problem, state, g)
        if A is None:
            blk = residuals(
                cm, g, meas, state.weights, inputs=problem.inputs, jacobian=True
            )
            # From the normal matrix: of the held Jacobian, or summed by blocks of
            # poses for large data (the analysis is the same either way).
            A, _ = block_normal(blk, np.arange(cm.size), np.ones(cm.size))
        tol = {"drop_tol": opts.drop_tol, "weak_tol": opts.weak_tol}
        every = np.ones(cm.size, bool)
        ident = identifiability_from_normal(A, cm.layout, every, **tol)
        found = _few_targets(problem, cm)
        specs = cm.layout.specs
        lost = tuple(
            d.name
            for d in ident.dropped
            if specs[cm.layout.index(d.name)].group in ("base", "cam")
        )
        if lost:
            found.append(
                Diagnostic(
                    "frames_undetermined",
                    f"the poses do not determine {', '.join(lost)}: the user frame and "
                    f"the tool offset trade off ({_why_frames_trade(cm.robot)}). They "
                    "are kept at their starting values; predictions at orientations "
                    "unlike the calibration poses can be far off. "
                    + _what_to_measure(cm.robot),
                    parameters=lost,
                    stage=self.name,
                )
            )
        if problem.n_residuals <= ident.free.sum():
            raise IdentifiabilityError(
                f"{meas.source}: {meas.n} poses ({problem.n_residuals} residuals) cannot "
                f"determine {int(ident.free.sum())} parameters."
            )
        out = state.but(free=ident.free, identifiability=ident).note(*found)
        return out.but(identified=out)


def _generic_normal(problem: Problem, state: State, g: Float) -> Float | None:
    """``JᵀJ`` at the generic point ``g`` from the Jacobian with the product columns
    kept at the state's point (registration's), where ``g`` differs from it only in
    compliances and link moments that are zero there (issue 36: one Jacobian pass
    fewer). There the deflections vanish, the moments' columns with them, and at ``g``,
    to first order in its tiny compliances, ``col(lambda_j) + sum_k s_k col(mu_jk)``
    and ``col(s_k) = sum_j lambda_j col(mu_jk)`` (:mod:`._lift`): ``Tᵀ A T`` with
    the products' normal matrix A (entries within ~1e-6 of the direct evaluation's,
    the same analysis). None where that does not hold."""
    cm, x = state.model, state.x
    moved = np.flatnonzero(g != x)
    kinds = {cm.layout.specs[i].kind for i in moved}
    if not kinds <= {"compliance", "moment"} or np.any(x[moved] != 0.0):
        return None
    P, K = cm.size, len(cm.link_products)
    blk = problem.evaluations.kept(cm, x, state.weights, P + K)
    if blk is None:
        return None
    A, _ = block_normal(blk, np.arange(P + K), np.ones(P + K))
    T = np.eye(P + K, P)
    for i, (lam, s) in enumerate(cm.link_products):
        T[P + i, lam] = g[s]
        T[P + i, s] = g[lam]
    return T.T @ A @ T


def _few_targets(problem: Problem, cm: CalibrationModel) -> list[Diagnostic]:
    """Sensor sets that see fewer than three targets, or all on one line."""
    meas = problem.meas
    if meas.kind != "sensor" or meas.targets is None:
        return []
    assert meas.target_index is not None
    found = []
    for si, label in enumerate(meas.set_labels):
        seen = np.unique(meas.target_index[meas.set_index == si])
        pts = meas.targets[seen]
        spread = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
        if seen.size < 3 or spread[1] < 1e-3 * max(spread[0], 1e-12):
            found.append(
                Diagnostic(
                    "targets_few",
                    f"set {label or '(default)'} sees {seen.size} target(s)"
                    + (" on one line" if seen.size >= 3 else "")
                    + ": the rotation of its user frame about the line through them "
                    "is not determined, so predictions at other targets are "
                    "unreliable. Measure at least three targets not on one line.",
                    parameters=tuple(cm.layout.names[i] for i in cm.base_index[si, 3:]),
                    stage="identifiability",
                )
            )
    return found


@dataclass(frozen=True, eq=False, repr=False)
class KinematicStage(Record):
    """Paper stage 1: the unified kinematic parameters by LM, with the joint-geometry
    priors (MAP). Without a pre-fit by :class:`Priors`, this is the first fit, and its
    residuals give the noise. With a robust loss, once more with the loss bending at
    three times a robust noise estimate (or ``f_scale_mm``)."""

    name: str = "stage 1: kinematic"
    settings: FitSettings | None = None  # None: from the problem's options

    def __call__(self, problem: Problem, state: State) -> State:
        kin = state.free & problem.kinematic
        prior = state.active_prior(problem.kinematic)
        state, res = run_lm(
            problem,
            state,
            self.name,
            state.x,
            kin,
            state.lm,
            prior,
            resume=state.prefit,  # the priors' pre-fit, when this fit goes on from it
            products=bool(state.model.link_products),  # stage 3 lifts from here
        )
        state = state.but(x=res.x)
        if problem.estimate_noise and not state.noise_estimated:
            state = estimate_noise(problem, state, state.x, kin, prior)
        opts = self.settings or FitSettings.of(problem.options)
        if opts.loss == "linear":
            return state
        r1 = problem.evaluations(state.model, state.x, state.weights).r
        if opts.f_scale_mm is not None:
            f_scale = opts.f_scale_mm * 1e-3 / median(state.weights.sigma)
        else:
            f_scale = 3.0 * robust_sigma(r1) * np.sqrt(r1.shape[1])
        lm = LMOptions(
            max_iter=opts.max_iter, loss=opts.loss, f_scale=f_scale, stol=STOL
        )
        state = state.but(lm=lm)
        state, res = run_lm(
            problem, state, f"{self.name} (robust)", state.x, kin, lm, prior
        )
        return state.but(x=res.x)


@dataclass(frozen=True, eq=False, repr=False)
class TransmissionStage(Record):
    """Paper stage 2: the Fourier coefficients of the transmission errors by linear least
    squares ('direct': on the whitened residuals; 'project': the residuals projected to
    joints by Eq. (29), then a Fourier fit per joint). Kept only if it lowers the error."""

    name: str = "stage 2: transmission"
    method: str | None = None  # 'direct', 'project' or 'none'; None: the options'

    def __call__(self, problem: Problem, state: State) -> State:
        method = self.method or problem.options.stage2
        cols = state.free & (problem.groups == "ntm")
        if not np.any(cols) or method == "none":
            return state
        ev, cm, w = problem.evaluations, state.model, state.weights
        before = ev.rms_mm(cm, state.x, w)
        t0 = time.perf_counter()
        problem.progress(self.name, method)
        fit = _stage2_project if method == "project" else _stage2_direct
        x2 = fit(problem, state, cols)
        after = ev.rms_mm(cm, x2, w)
        if after > before:  # a linear fit cannot be trusted to help: keep stage 1
            x2, after = state.x, before
        entry = StageLog(
            f"{self.name} ({method})",
            int(cols.sum()),
            before,
            after,
            1,
            "linear",
            True,
            time.perf_counter() - t0,
        )
        # Stage 3 lifts from stage 1's solution, where this fit is linear.
        return state.but(x=x2, stages=(*state.stages, entry), linearised=state.x)


def _stage2_direct(problem: Problem, state: State, cols: np.ndarray) -> Float:
    """Fourier coefficients by linear least squares on the whitened residuals."""
    blk = problem.evaluations(state.model, state.x, state.weights, jacobian=True)
    idx = np.flatnonzero(cols)
    if blk.J is not None:
        A = blk.J[:, :, idx].reshape(-1, idx.size)
        delta, *_ = np.linalg.lstsq(A, -blk.r.reshape(-1), rcond=None)  # Eq. (T-1)
    else:  # large data: the same least squares by its normal equations
        N_, g_ = block_normal(blk, idx, np.ones(idx.size))
        delta = -spd_solve(N_, g_, rcond=1e-15)  # Eq. (T-1)
    out = state.x.copy()
    out[idx] += delta
    return out


def _stage2_project(problem: Problem, state: State, cols: np.ndarray) -> Float:
    """The paper's stage 2: residuals to joint space by Eq. (29), then a Fourier fit of
    each joint's errors (Eq. 17) by linear least squares (the samples are not uniform in
    angle, so not a DFT)."""
    cm, meas = state.model, problem.meas
    spec = cm.spec
    joints = list(spec.ntm_joints)
    blk = problem.evaluations(cm, state.x, state.weights)
    Jq = cm.joint_jacobian(state.x, problem.inputs)[:, :3, :]  # (N, 3, n) position
    Jt = Jq[:, :, [j - 1 for j in joints]]
    e = -blk.raw_position  # joint errors that would remove the residual
    if len(joints) == 3:
        dth = np.linalg.solve(Jt, e[:, :, None])[:, :, 0]  # Eq. (29), per point 3x3
    else:
        dth = (np.linalg.pinv(Jt) @ e[:, :, None])[:, :, 0]  # Eq. (29), least squares
    out = state.x.copy()
    specs = cm.layout.specs
    all_cols = (["k0"] if spec.ntm_offset else []) + [
        f"k{ab}{h}" for h in range(1, spec.ntm_order + 1) for ab in "ab"
    ]
    for k, j in enumerate(joints):
        idx = np.intersect1d(
            cm.layout.select(group="ntm", joint=j), np.flatnonzero(cols)
        )
        if idx.size == 0:
            continue
        B = ntm_basis(meas.q_ctrl[:, j - 1], spec.ntm_order, spec.ntm_offset)
        Bsel = B[:, [all_cols.index(specs[i].field) for i in idx]]
        coef, *_ = np.linalg.lstsq(Bsel, dth[:, k], rcond=None)  # Eq. (17) fitted
        out[idx] += coef
    return out


@dataclass(frozen=True, eq=False, repr=False)
class FullStage(Record):
    """Paper stage 3: every identifiable parameter together, from the lifted start of the
    link products, with all priors. Without sigmas in the data, the noise is estimated
    again from its residuals (Helmert, per set or marker where they differ); while a
    sigma moves by more than 20 %, once more with it (the priors were weighed against
    the wrong noise). ``screen``: a fit whose ``s0`` alone is read (the nominal
    check's screen): it stops on the pre-fits' statistical tolerance
    (:data:`STOL_PRE`) and evaluates no Jacobian at its solution."""

    name: str = "stage 3: all"
    screen: bool = False

    def __call__(self, problem: Problem, state: State) -> State:
        if not np.any(state.free & ~problem.kinematic):
            return state
        lm3 = replace(state.lm, max_iter=max(state.lm.max_iter, 200))
        if self.screen:
            lm3 = replace(lm3, stol=max(lm3.stol, STOL_PRE))
        prior = state.active_prior()
        fit = partial(run_lm, lifted=True, final_jacobian=not self.screen)
        at = state.linearised  # stage 2's point: the lifted start's linearisation
        state, res = fit(
            problem, state, self.name, state.x, state.free, lm3, prior, lift_at=at
        )
        state = state.but(x=res.x, linearised=None)
        for _ in range(_NOISE_ROUNDS if problem.estimate_noise else 0):
            # Variance components iterated with the fit (Eq. (T-7)): the priors were
            # weighed against the noise of the earlier, smaller models.
            new = estimate_noise(problem, state, state.x, state.free, prior)
            if _noise_moved(state.weights, new.weights) <= np.log(_NOISE_TOL):
                state = new  # the estimate at this fit; no refit for a small change
                break
            state, res = fit(problem, new, self.name, state.x, state.free, lm3, prior)
            state = state.but(x=res.x)
        return state


def _noise_moved(a: Weights, b: Weights) -> float:
    """Largest change of a sigma between two noise models (log ratio)."""
    moved = np.abs(np.log(b.sigma / a.sigma))
    if a.sigma_rot is not None and b.sigma_rot is not None:
        moved = np.maximum(moved, np.abs(np.log(b.sigma_rot / a.sigma_rot)))
    return float(moved.max())


def run_shared(problem: Problem, state: State, stages: Sequence[Stage]) -> State:
    """``stages`` on every row of ``problem``; when they begin with :class:`Register` and
    :class:`Identify`, which depend on neither the loss nor the priors, from ``state``'s
    own state after them (:attr:`State.identified`, when made on every row): the same
    numbers without computing them again (the rejection's robust probe: three Jacobian
    passes fewer)."""
    start = state.identified
    if (
        start is not None
        and start.active is None
        and len(stages) >= 2
        and isinstance(stages[0], Register)
        and isinstance(stages[1], Identify)
    ):
        return run_stages(problem, start, stages[2:])
    return run_stages(problem, problem.start(), stages)


def _axes_parallel(robot) -> bool:
    """All turning joint axes parallel (a SCARA, a gantry with one rotary axis, a planar
    arm): the tool turns about them only."""
    from kinecal.robot import dh_transforms

    ch = robot.dh_chain()
    rows = dh_transforms(ch.theta_offset, ch.d, ch.a, ch.alpha)[:, :3, :3]
    R, axes = np.eye(3), []
    for k in range(len(rows)):  # joint k turns about z of DH frame k - 1
        if not ch.prismatic[k]:
            axes.append(R[:, 2])
        R = R @ rows[k]
    return len(axes) < 2 or bool(np.linalg.matrix_rank(np.array(axes), tol=1e-9) < 2)


def _why_frames_trade(robot) -> str:
    if _axes_parallel(robot):
        return "the robot turns the tool about parallel axes only"
    return "too little variation of the tool orientation"


def _what_to_measure(robot) -> str:
    if _axes_parallel(robot):
        return (
            "No poses of this robot can: set the tool offset along its axes from a "
            "measured tool length."
        )
    return "Measure with varied orientations."
