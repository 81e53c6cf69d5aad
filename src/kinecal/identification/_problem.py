"""The two objects every calibration stage works on: the problem and the state.

A stage is a callable ``stage(problem, state) -> state`` (:class:`Stage`). The
:class:`Problem` holds what does not change during a calibration (robot, data, model
structure, options, the evaluation cache); the :class:`State` holds what the stages
build up (parameters, which of them are free, weights, priors, logs and diagnostics).
States are immutable: a stage returns a new one (:meth:`State.but`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np

from kinecal._record import ReprRecord
from kinecal.errors import (
    ConfigError,
    DataError,
    IdentifiabilityError,
    described,
    expect_type,
)
from kinecal.identification._identifiability import Identifiability
from kinecal.identification._lm import LMOptions, Prior
from kinecal.identification._options import (
    KINEMATIC_GROUPS,
    STOL,
    CalibrationOptions,
)
from kinecal.identification._reweight import nbytes, raw_errors, reweighted
from kinecal.measurement._diagnostics import Diagnostic, Outlier, StageLog
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._residuals import ResidualBlock, Weights, residuals
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = [
    "EvaluationCache",
    "Problem",
    "Stage",
    "State",
    "Ticker",
    "Workspace",
    "run_stages",
]

Progress = Callable[[str, str], None]

# Inside a stage, a progress line at most this often [s] (solver iterations, passes over
# the poses of large data); each stage's start is always reported.
REPORT_EVERY = 1.0
# A calibration result keeps the evaluations at its solution (for the nominal check's fit
# from there) when they take at most this many bytes (data of a few thousand poses).
# More is not kept: the fresh memory a larger cache takes costs more (page faults) than
# the Jacobian passes it saves (issue 36: 0.12 s of system time in the default command).
RETAIN_BYTES = 16 * 2**20
# Points whose raw errors a cache keeps after their blocks (a quarter of RETAIN_BYTES
# at most: 32 points of 2000 poses take 3 MB).
_RAW_POINTS = 32


class Ticker:
    """A calibration's progress callback ``say(stage, detail)``, which long stages also
    tell how they get on: solver iterations (:meth:`iteration`) and passes over the
    poses of large data (:meth:`rows`, with the time left in the pass), at most one line
    every :data:`REPORT_EVERY` seconds."""

    def __init__(self, say: Progress) -> None:
        self.say = say
        self.stage = ""
        self._last = time.perf_counter()
        self._in_pass = False
        self._pass_t0, self._pass_first, self._pass_prev = self._last, 0, 0

    def __call__(self, stage: str, detail: str = "") -> None:
        self.stage = stage
        self._last = time.perf_counter()
        self.say(stage, detail)

    def _due(self) -> bool:
        return time.perf_counter() - self._last >= REPORT_EVERY

    def _emit(self, detail: str) -> None:
        self._last = time.perf_counter()
        self.say(self.stage, detail)

    def iteration(self, label: str, it: int, cost: float, change: float) -> None:
        """After solver iteration ``it`` of ``label`` (cost and its relative change)."""
        if self._due():
            self.stage = label
            self._emit(f"iteration {it}, cost {cost:.6g} ({change:+.2%})")

    def beat(self, what: str) -> None:
        """A long loop's progress, in words."""
        if self._due():
            self._emit(what)

    def rows(self, done: int, total: int) -> None:
        """``done`` of ``total`` poses evaluated in the current pass over large data."""
        now = time.perf_counter()
        if not self._in_pass or done <= self._pass_prev:  # a pass begins
            self._in_pass, self._pass_t0, self._pass_first = True, now, done
        self._pass_prev = done
        if done >= total:
            self._in_pass = False
        elif self._due() and done > self._pass_first:
            rate = (now - self._pass_t0) / (done - self._pass_first)
            self._emit(
                f"{done:,} of {total:,} poses ({done / total:.0%}), about "
                f"{(total - done) * rate:.1f} s left in this pass"
            )


class EvaluationCache:
    """Residual blocks of one calibration: each point is evaluated once.

    The identification revisits points (a stage starts where the last one ended, the
    priors, stage 2 and the uncertainty look at a stage's solution, the log reports the
    error before and after each stage). The last few blocks are kept, keyed by the model,
    the parameters and the weights; raw position errors do not depend on the weights.
    Each block also keeps the model's forward state, so the Jacobian at a point evaluated
    before (the LM's accepted trial point, typically) skips the forward kinematics, and a
    Jacobian kept at a point serves new weights there too, rescaled (the noise
    re-estimation's refit starts where the last fit ended).
    """

    def __init__(self, meas: Measurements, inputs: ModelInputs, keep: int = 3) -> None:
        self.meas = meas
        self.inputs = inputs
        self.keep = keep
        self._blocks: list[tuple[CalibrationModel, bytes, Weights, ResidualBlock]] = []
        # The raw errors of the last points pushed out of _blocks (a result's "before"
        # at the registered point is asked for long after: issue 36, one pass fewer).
        self._raw: list[tuple[CalibrationModel, bytes, Weights, ResidualBlock]] = []

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
        other = None  # a held Jacobian at x under other weights, to be reweighted
        for m, k, ww, blk in reversed(self._blocks):
            if m is cm and k == key:
                if ww is w and (not jacobian or blk.has_jacobian(n_cols)):
                    return blk
                forward = forward or blk.forward
                if other is None and blk.J is not None and blk.J.shape[-1] >= n_cols:
                    other = (ww, blk)
        if not jacobian and forward is None:
            for m, k, ww, blk in reversed(self._raw):
                if m is cm and k == key:
                    return raw_errors(blk, ww, w)
        if jacobian and other is not None:
            blk = reweighted(other[1], other[0], w)
        else:
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
        self._push((cm, key, w, blk))
        return blk

    def _push(
        self, entry: tuple[CalibrationModel, bytes, Weights, ResidualBlock]
    ) -> None:
        """Keep ``entry``; the raw errors of the one it pushes out stay at hand."""
        kept = self._blocks[-(self.keep - 1) :]
        out = self._blocks[: len(self._blocks) - len(kept)]
        raw = [(m, k, w, raw_errors(b, w, w)) for m, k, w, b in out]
        raw = [*self._raw, *raw]
        self._raw = raw[max(len(raw) - _RAW_POINTS, 0) :]
        while sum(nbytes(e[3]) for e in self._raw) > RETAIN_BYTES // 4:
            self._raw.pop(0)
        self._blocks = [*kept, entry]

    def at(
        self, cm: CalibrationModel, x: Float, limit: int, before: Float | None = None
    ) -> EvaluationCache | None:
        """A cache of the blocks kept at ``x`` alone (and the raw errors kept at
        ``before``), or None when there are none or they take more than ``limit``
        bytes."""
        key = np.asarray(x, np.float64).tobytes()
        mine = [e for e in self._blocks if e[0] is cm and e[1] == key]
        if not mine or sum(nbytes(e[3]) for e in mine) > limit:
            return None
        out = EvaluationCache(self.meas, self.inputs, self.keep)
        out._blocks = mine
        if before is not None:
            key = np.asarray(before, np.float64).tobytes()
            out._raw = [e for e in self._raw if e[0] is cm and e[1] == key][-1:]
        return out

    def put(
        self, cm: CalibrationModel, x: Float, w: Weights, blk: ResidualBlock
    ) -> None:
        """Keep ``blk``, evaluated elsewhere, as the block at ``x`` under ``w``."""
        self._push((cm, np.asarray(x, np.float64).tobytes(), w, blk))

    def kept(
        self, cm: CalibrationModel, x: Float, w: Weights, n_cols: int = 0
    ) -> ResidualBlock | None:
        """The block kept at ``x`` under the weights ``w`` with its Jacobian held (or,
        given ``n_cols``, any that gives Jacobians of so many columns), if any (never
        evaluates)."""
        key = np.asarray(x, np.float64).tobytes()
        for m, k, ww, blk in reversed(self._blocks):
            if m is cm and k == key and ww is w:
                if blk.has_jacobian(n_cols) if n_cols else blk.J is not None:
                    return blk
        return None

    def raw_position(self, cm: CalibrationModel, x: Float, w: Weights) -> Float:
        """Position errors (N, 3) at ``x`` [m], from any block kept at that point."""
        key = np.asarray(x, np.float64).tobytes()
        for m, k, _, blk in reversed([*self._raw, *self._blocks]):
            if m is cm and k == key:
                return blk.raw_position
        return self(cm, x, w).raw_position

    def rms_mm(self, cm: CalibrationModel, x: Float, w: Weights) -> float:
        """RMS of the 3-D position errors at ``x`` [mm]."""
        e_p = self.raw_position(cm, x, w)
        return float(np.sqrt(np.mean(np.sum(e_p**2, axis=1)))) * 1e3


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
    options = {"ntm_joints": robot.ntm_joints, **options}
    return ModelSpec.preset(
        model,
        cam_rotation=cam_rotation,
        sets=meas.set_labels,
        markers=meas.marker_labels,
        has_self_weight=robot.self_weight is not None,
        link_bodies=robot.link_bodies,
        **options,  # type: ignore[arg-type]
    )


class Workspace:
    """The caches of a calibration, beside its constant :class:`Problem`.

    What the stages compute and may need again lives here, not in the problem: the
    evaluations at the last points visited (:class:`EvaluationCache`: a stage starts
    where the last one ended, the uncertainty and the diagnosis read the Jacobian at
    the solution) and the workspace of the rows a state uses when they are not all
    (:meth:`subset`, one at a time: rejection moves on). A result keeps the evaluations
    at its solution (:meth:`at`), where the nominal check's fit starts (:meth:`copy`).
    """

    def __init__(
        self,
        meas: Measurements,
        inputs: ModelInputs,
        evaluations: EvaluationCache | None = None,
    ) -> None:
        self.meas, self.inputs = meas, inputs
        self.evaluations = evaluations or EvaluationCache(meas, inputs)
        self._subsets: dict[bytes, Workspace] = {}

    def at(
        self, cm: CalibrationModel, x: Float, before: Float | None = None
    ) -> Workspace | None:
        """A workspace with this one's evaluations at ``x`` alone (what a result keeps
        for fits from its solution; with the raw errors at ``before``, its registered
        point), or None when they take more than :data:`RETAIN_BYTES`."""
        kept = self.evaluations.at(cm, x, RETAIN_BYTES, before)
        return None if kept is None else Workspace(self.meas, self.inputs, kept)

    def copy(self) -> Workspace:
        """A workspace starting with this one's evaluations, which its own do not
        change (a fit from a result's solution leaves the result's as they are)."""
        ev = EvaluationCache(self.meas, self.inputs, self.evaluations.keep)
        ev._blocks = list(self.evaluations._blocks)
        ev._raw = list(self.evaluations._raw)
        return Workspace(self.meas, self.inputs, ev)

    def subset(
        self, active: np.ndarray, reference_payload_kg: float | None
    ) -> Workspace:
        """The workspace of the rows ``active`` (kept until another subset is asked)."""
        key = np.packbits(active).tobytes()
        sub = self._subsets.get(key)
        if sub is None:
            meas = self.meas.subset(active)
            inputs = meas.model_inputs(reference_payload_kg)
            sub = Workspace(meas, inputs)
            self._subsets.clear()  # one subset at a time: rejection moves on
            self._subsets[key] = sub
        return sub


@dataclass(frozen=True, eq=False, repr=False)
class Problem(ReprRecord):
    """What a calibration works on: constant (its caches are in its :class:`Workspace`).

    Attributes
    ----------
    robot, meas, options :
        The robot, the data (SI) and the settings.
    model : CalibrationModel
        The model structure at nominal kinematics (a stage may replace the state's model by
        one with other reference rotations, never with another layout).
    inputs : ModelInputs of ``meas``.
    workspace : Workspace, the caches (``evaluations``); a problem made with another
        calibration's (:meth:`make`) starts with its evaluations.
    reference_payload_kg : the payload defining the unit weight of lambda*.
    groups : (P,) group of every parameter ('base', 'joint', 'cam', 'ntm', 'load', 'link').
    kinematic : (P,) bool, the unified kinematic parameters (stage 1).
    frames : (P,) bool, the user and cam frame parameters (registration).
    root : the problem on every row of the data, when this one is restricted to some
        (:meth:`on`); None for the root itself.
    """

    robot: RobotDescription
    meas: Measurements
    options: CalibrationOptions
    model: CalibrationModel
    inputs: ModelInputs
    workspace: Workspace = field(repr=False)
    reference_payload_kg: float | None
    groups: np.ndarray
    kinematic: np.ndarray
    frames: np.ndarray
    progress: Ticker = field(default_factory=lambda: Ticker(lambda stage, detail: None))
    root: Problem | None = None

    @classmethod
    def make(
        cls,
        robot: RobotDescription,
        meas: Measurements,
        model: str | ModelSpec = "full",
        options: CalibrationOptions | None = None,
        progress: object | None = None,
        *,
        workspace: Workspace | None = None,
    ) -> Problem:
        """Check that the data can determine the model and set the problem up.

        ``workspace``: the caches of another problem on the same data (``meas`` itself)
        to share (a fit with other options: the nominal check); default new ones.

        Raises
        ------
        DataError
            The data does not fit the robot (joint count).
        IdentifiabilityError
            Fewer residuals than parameters.
        """
        expect_type(robot, RobotDescription, "robot", "kinecal.robot.load_robot")
        expect_type(meas, Measurements, "meas", "kinecal.io.read_measurements")
        if options is not None:
            expect_type(options, CalibrationOptions, "options")
        if not isinstance(model, (str, ModelSpec)):
            raise ConfigError(
                f"model: expected a preset name (kinematic, ntm, rfcm, full) or a "
                f"ModelSpec; got {described(model)}."
            )
        if meas.n_joints != robot.n_joints:
            raise DataError(
                f"{meas.source} has {meas.n_joints} joint columns; robot {robot.name} "
                f"has {robot.n_joints} joints."
            )
        data_payload = meas.reference_payload()
        if robot.link_masses and data_payload and data_payload != robot.payload_kg:
            # The link masses' nominal ratios are per unit of the reference payload.
            robot = replace(robot, payload_kg=data_payload)
        spec = spec_for(robot, meas, model)
        if spec.load and meas.payload_kg is not None and data_payload is None:
            raise DataError(
                f"{meas.source}: column 'payload_kg' is 0 in every row, so the "
                f"'{spec.name}' model's payload compliance cannot be calibrated; "
                "expected some rows with a payload (0 kg rows beside them are fine), "
                "or leave the column out (the compliance is then per unit of the "
                "load the robot carried), or a model without it (kinematic, ntm)."
            )
        cm = CalibrationModel(robot, spec)
        c = meas.components
        if meas.n * c <= cm.size:
            raise IdentifiabilityError(
                f"{meas.source}: {meas.n} poses give {meas.n * c} residuals, but the "
                f"'{spec.name}' model has {cm.size} parameters; measure at least "
                f"{cm.size // c + 1} poses (several times more for a reliable result)."
            )
        ref_payload = meas.reference_payload() or robot.payload_kg
        groups = np.array([s.group for s in cm.layout.specs])
        if workspace is None or workspace.meas is not meas:
            workspace = Workspace(meas, meas.model_inputs(ref_payload))
        if isinstance(progress, Ticker):
            say = progress
        else:
            say = Ticker(progress if callable(progress) else (lambda s, d: None))
        kinematic = np.isin(groups, KINEMATIC_GROUPS)
        frames = np.isin(groups, ("base", "cam"))
        for a in (groups, kinematic, frames):
            a.flags.writeable = False
        return cls(
            robot,
            meas,
            options or CalibrationOptions(),
            cm,
            workspace.inputs,
            workspace,
            ref_payload,
            groups,
            kinematic,
            frames,
            say,
        )

    @property
    def evaluations(self) -> EvaluationCache:
        """The evaluations of this problem's rows (its workspace's cache)."""
        return self.workspace.evaluations

    def on(self, state: State) -> Problem:
        """The problem on the rows the state uses (``state.active``; all by default).

        The rows' workspace is kept, so the stages that follow one another on the same
        rows share their evaluations.
        """
        root = self.root or self
        if state.active is None or state.active.all():
            return root
        sub = root.workspace.subset(state.active, root.reference_payload_kg)
        return replace(root, meas=sub.meas, inputs=sub.inputs, workspace=sub, root=root)

    def with_options(self, options: CalibrationOptions) -> Problem:
        """The same root problem with other options and a workspace of its own (a fit
        with other options visits other points: sharing the last few evaluations would
        push out the ones this problem's stages come back to)."""
        root = self.root or self
        return replace(
            root, options=options, workspace=Workspace(root.meas, root.inputs)
        )

    @property
    def n_residuals(self) -> int:
        """Residual components of the data (rows times 3 or 6)."""
        return self.meas.n * self.meas.components

    @property
    def estimate_noise(self) -> bool:
        """Whether the noise comes from the residuals (no sigmas in the data)."""
        return self.options.tuning.variance_components and self.meas.sigma is None

    def start(self, active: np.ndarray | None = None) -> State:
        """The state before any stage: nominal parameters, default weights, on the rows
        ``active`` of the data (all by default)."""
        root = self.root or self
        state = State(
            model=root.model,
            x=root.model.nominal.copy(),
            weights=Weights.default(root.meas),
            lm=LMOptions(max_iter=root.options.tuning.max_iter, stol=STOL),
            free=np.ones(root.model.size, bool),
        )
        if active is None:
            return state
        state = state.but(active=np.asarray(active, bool))
        return state.but(weights=Weights.default(root.on(state).meas))


@dataclass(frozen=True, eq=False, repr=False)
class State(ReprRecord):
    """What the stages have found so far.

    Attributes
    ----------
    model : CalibrationModel (the problem's, with the reference rotations registration set)
    x : (P,) current parameters (SI).
    weights : Weights, the sigmas that whiten the residuals.
    lm : LMOptions of the data term (its loss and where it bends).
    free : (P,) bool, parameters to estimate (after the identifiability analysis: the
        identifiable ones).
    x_registered : (P,) parameters after registration (the "before calibration" state).
    identifiability : Identifiability or None.
    prior : Prior or None, the Gaussian priors (``inf``: none for that parameter).
    prior_factors : scales applied to the groups' priors by maximum evidence.
    noise_estimated : whether the noise was estimated from the residuals.
    noise_groups : how the noise estimate grouped the residuals, in words.
    noise : the estimated noise when the fit weighs the data otherwise (orientations
        down-weighted to predict positions better); None when ``weights`` is the noise.
    covariance, std, sigma0 : uncertainty at the solution (after :class:`Uncertainty`).
    active : (N,) bool over the rows of the data, the rows in use (None: all); rows that
        robust rejection excluded are False.
    rejected : the rows excluded as gross errors, with their errors and z.
    outliers : rows improbable under the fitted noise (after :class:`Diagnose`).
    stages, diagnostics : the log of every solver run and every finding.
    identified : the state right after registration and the identifiability analysis
        (:class:`~kinecal.identification._stages.Identify`) on the same rows, or None.
        Neither depends on the loss or the priors, so fits with other options on these
        rows (the rejection's robust probe, the nominal check) start from it instead of
        computing it again (issue 36).
    prefit : on the :attr:`identified` state, the priors' unconstrained stage-1 pre-fit
        from it (a :class:`~kinecal.identification._solve.SolverRun`), which stage 1
        without priors from that state continues instead of repeating it (the same
        iterates: the rejection's probe, the nominal check); None otherwise.
    """

    model: CalibrationModel
    x: Float
    weights: Weights
    lm: LMOptions
    free: np.ndarray
    x_registered: Float | None = None
    identifiability: Identifiability | None = None
    prior: Prior | None = None
    prior_factors: dict[str, float] = field(default_factory=dict)
    noise_estimated: bool = False
    noise_groups: tuple[str, ...] = ()
    noise: Weights | None = None
    covariance: Float | None = None
    std: Float | None = None
    sigma0: float = float("nan")
    active: np.ndarray | None = None
    rejected: tuple[Outlier, ...] = ()
    outliers: tuple[Outlier, ...] = ()
    stages: tuple[StageLog, ...] = ()
    diagnostics: tuple[Diagnostic, ...] = ()
    identified: State | None = field(default=None, repr=False)
    prefit: object | None = field(default=None, repr=False)
    # Stage 2's point of linearisation (stage 1's solution), where stage 3 lifts from.
    linearised: Float | None = field(default=None, repr=False)

    def but(self, **changes: object) -> State:
        """A copy with some fields changed."""
        return replace(self, **changes)  # type: ignore[arg-type]

    def note(self, *found: Diagnostic) -> State:
        """A copy with diagnostics added."""
        return replace(self, diagnostics=(*self.diagnostics, *found))

    def active_prior(self, mask: np.ndarray | None = None) -> Prior | None:
        """The prior restricted to ``mask`` (default: all), or None when it holds none of
        the free parameters there."""
        if self.prior is None:
            return None
        keep = self.free if mask is None else self.free & mask
        if not np.any(np.isfinite(self.prior.sigma) & keep):
            return None
        if mask is None:
            return self.prior
        return Prior(self.prior.mean, np.where(mask, self.prior.sigma, np.inf))


def run_stages(problem: Problem, state: State, stages: Iterable[Stage]) -> State:
    """Run ``stages`` in order, each on the rows its input state uses."""
    for stage in stages:
        state = stage(problem.on(state), state)
    return state


class Stage(Protocol):
    """A step of the identification: ``stage(problem, state) -> state``."""

    @property
    def name(self) -> str: ...

    def __call__(self, problem: Problem, state: State) -> State: ...
