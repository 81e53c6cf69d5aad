"""Calibration as a recipe of stages (paper Sec. 4, Fig. 6), from nominal kinematics alone.

:func:`calibrate` runs :func:`default_stages` on a :class:`Problem`: registration of the
user and cam frames, the identifiability analysis, the priors, the paper's three stages
(kinematic; transmission; everything), the evidence scaling of the compliance priors,
robust rejection, the uncertainty and the diagnostics. Each stage is a small object
``stage(problem, state) -> state`` (:mod:`._stages`, :mod:`._priors`,
:mod:`._uncertainty`); a caller may run a list of their own (``stages=``).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal._record import MutableRecord
from kinecal.identification._diagnose import Diagnose
from kinecal.identification._identifiability import (
    Identifiability,
    correlation_from_covariance,
)
from kinecal.identification._lm import Prior
from kinecal.identification._noise import NoiseModel
from kinecal.identification._options import (
    PRIOR_SIGMA,
    CalibrationOptions,
    FitSettings,
    IdentifySettings,
    PriorSettings,
    RejectSettings,
)
from kinecal.identification._priors import EvidencePriors, Priors, build_prior
from kinecal.identification._problem import (
    Problem,
    Stage,
    State,
    Workspace,
    run_stages,
    spec_for,
)
from kinecal.identification._robust import RobustRejection, chi2_isf
from kinecal.identification._stages import (
    FullStage,
    Identify,
    KinematicStage,
    Register,
    TransmissionStage,
)
from kinecal.identification._uncertainty import Uncertainty
from kinecal.measurement._blocks import reporting
from kinecal.measurement._calibrated import CalibratedModel
from kinecal.measurement._diagnostics import Diagnostic, Outlier, StageLog
from kinecal.measurement._measurements import Measurements
from kinecal.measurement._metrics import Metrics, metrics_from_errors
from kinecal.measurement._residuals import Weights
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = [
    "PRIOR_SIGMA",
    "CalibrationOptions",
    "CalibrationResult",
    "Outlier",
    "StageLog",
    "build_prior",
    "calibrate",
    "chi2_isf",
    "default_stages",
    "spec_for",
]


def default_stages(options: CalibrationOptions | None = None) -> tuple[Stage, ...]:
    """The identification of Fig. 6 with kinecal's additions, in order, each with its
    settings from ``options`` (without options, each reads them from the problem's
    options when it runs)."""
    o = options
    fit_s = FitSettings.of(o) if o else None
    prior_s = PriorSettings.of(o) if o else None
    reject_s = RejectSettings.of(o) if o else None
    fit = (
        Register(),  # closed-form frames, LM on them: the "before" state
        Identify(settings=IdentifySettings.of(o) if o else None),  # what is held
        Priors(settings=prior_s),  # physical priors, geometry ones adapted to the data
        KinematicStage(settings=fit_s),  # paper stage 1
        TransmissionStage(method=o.stage2 if o else None),  # paper stage 2
        FullStage(),  # paper stage 3
        NoiseModel(),  # pose data: the orientation weight that predicts positions best
        EvidencePriors(settings=prior_s),  # compliance priors by maximum evidence
    )
    # A robust kinematic fit finds the suspects.
    probe = (*fit[:2], KinematicStage(settings=_robust_fit(fit_s)))
    return (
        *fit,
        # gross errors out: the fit again on clean rows
        RobustRejection(fit, probe, settings=reject_s),
        Uncertainty(),
        Diagnose(settings=reject_s, priors=prior_s),
    )


def _robust_fit(fit: FitSettings | None) -> FitSettings | None:
    """The settings of the rejection's robust probe: a Huber loss for the linear one."""
    if fit is None or fit.loss != "linear":
        return fit
    return replace(fit, loss="huber")


@one_blas_thread()
def calibrate(
    robot: RobotDescription,
    meas: Measurements,
    model: str | ModelSpec = "full",
    options: CalibrationOptions | None = None,
    *,
    stages: Sequence[Stage] | None = None,
    progress: object | None = None,
    start: State | None = None,
) -> CalibrationResult:
    """Identify a model from measurements, starting from nominal kinematics alone.

    Parameters
    ----------
    robot : RobotDescription
    meas : Measurements
    model : preset name ('kinematic', 'ntm', 'rfcm', 'full') or a ModelSpec
    options : CalibrationOptions
    stages : the stages to run, default :func:`default_stages`
    progress : callable ``progress(stage: str, detail: str)``, optional
    start : the state to run ``stages`` from (default: the nominal start), e.g. another
        calibration's ``identified`` state on the same data with the stages after
        :class:`Identify`

    Returns
    -------
    CalibrationResult
        Non-convergence is reported in ``success`` and ``diagnostics``, not raised.

    Raises
    ------
    DataError
        The data does not fit the robot (joint count).
    IdentifiabilityError
        Too few poses for the model.
    """
    problem = Problem.make(robot, meas, model, options, progress)
    return calibrate_problem(problem, stages, start)


def calibrate_problem(
    problem: Problem,
    stages: Sequence[Stage] | None = None,
    start: State | None = None,
) -> CalibrationResult:
    """:func:`calibrate` of a problem set up (:meth:`Problem.make`; with another
    calibration's workspace, say)."""
    t_start = time.perf_counter()
    recipe = default_stages(problem.options) if stages is None else stages
    # Passes over large data and other long loops report too.
    with reporting(problem.progress.rows, problem.progress.beat):
        state = run_stages(problem, problem.start() if start is None else start, recipe)
        problem.progress("result", "errors before and after")
        return CalibrationResult.from_state(
            problem, state, time.perf_counter() - t_start
        )


@dataclass(eq=False, repr=False)
class CalibrationResult(MutableRecord):
    """Everything :func:`calibrate` found.

    Attributes
    ----------
    calibrated : CalibratedModel, the identified model (what ``model.yaml`` stores).
    registered : (P,) parameters after registration only (nominal kinematics with fitted
        user and cam frames): the "before" state.
    covariance : (P, P) parameter covariance (zero rows for parameters not estimated).
    identifiability : Identifiability
    stages : list of StageLog
    metrics_before, metrics_after : Metrics on the calibration data.
    outliers : rows kept whose errors are improbable under the noise of the others.
    rejected : rows rejected as gross errors and left out of the fit (with their error
        and z at the final fit; never dropped silently: also in ``diagnostics``).
    diagnostics : every finding of the stages (:class:`Diagnostic`, with a code).
    success : bool, every stage converged.
    sigma0 : a-posteriori standard deviation of unit weight.
    prior_factors : scale applied to each group's default prior by maximum evidence
        (transmission 'ntm', payload 'load', link weight 'link'); empty if not tuned.
    identified : the state after registration and the identifiability analysis on the
        rows of the final fit (:attr:`State.identified`), for fits with other options that
        start from it (``calibrate(..., start=)``); None when the stages had none.
    workspace : the evaluations at the solution on the rows of the fit (a workspace
        with those alone, when they take at most 16 MB), for fits with other options
        from there (the nominal check); None otherwise.
    """

    calibrated: CalibratedModel
    registered: Float
    covariance: Float
    identifiability: Identifiability
    stages: list[StageLog]
    metrics_before: Metrics
    metrics_after: Metrics
    outliers: list[Outlier]
    diagnostics: list[Diagnostic]
    rejected: list[Outlier]
    success: bool
    sigma0: float
    weights: Weights
    seconds: float
    prior: Prior | None = None
    prior_factors: dict[str, float] = field(default_factory=dict)
    identified: State | None = field(default=None, repr=False)
    workspace: Workspace | None = field(default=None, repr=False, compare=False)

    @classmethod
    def from_state(
        cls, problem: Problem, state: State, seconds: float = 0.0
    ) -> CalibrationResult:
        """The result of the stages that produced ``state`` (on the rows it uses)."""
        problem = problem.on(state)
        cm, meas = state.model, problem.meas
        x_reg = state.x_registered if state.x_registered is not None else state.x
        ev = problem.evaluations
        before = ev(cm, x_reg, state.weights)
        after = ev(cm, state.x, state.weights)
        std = state.std if state.std is not None else np.full(cm.size, np.nan)
        ident = state.identifiability
        if ident is None:
            ident = Identifiability(
                cm.layout.names, state.free, state.free, np.full(cm.size, np.nan)
            )
        calibrated = CalibratedModel(
            cm,
            state.x,
            std,
            ["estimated" if f else "unidentifiable" for f in state.free],
            problem.reference_payload_kg,
            info={
                "source": meas.source,
                "kind": meas.kind,
                "n": meas.n,
                "model": cm.spec.name,
                "calibrated_joint_range": _joint_range(meas, problem.robot),
                **(
                    {"rejected_rows": [o.row for o in state.rejected]}
                    if state.rejected
                    else {}
                ),
            },
        )
        return cls(
            calibrated=calibrated,
            registered=x_reg,
            covariance=(
                state.covariance
                if state.covariance is not None
                else np.zeros((cm.size, cm.size))
            ),
            identifiability=ident,
            stages=list(state.stages),
            metrics_before=metrics_from_errors(
                before.raw_position, before.raw_rotation
            ),
            metrics_after=metrics_from_errors(after.raw_position, after.raw_rotation),
            outliers=list(state.outliers),
            diagnostics=list(state.diagnostics),
            rejected=list(state.rejected),
            success=all(s.success for s in state.stages),
            sigma0=state.sigma0,
            weights=state.weights,
            seconds=seconds,
            prior=state.active_prior(),
            prior_factors=dict(state.prior_factors),
            identified=state.identified,
            workspace=problem.workspace.at(cm, state.x, x_reg),
        )

    @property
    def warnings(self) -> list[str]:
        """The messages of the diagnostics a user should see, in the order found."""
        return [d.message for d in self.diagnostics if d.severity == "warning"]

    def diagnostics_with(self, code: str) -> list[Diagnostic]:
        """The diagnostics of one code."""
        return [d for d in self.diagnostics if d.code == code]

    @property
    def model(self) -> CalibrationModel:
        return self.calibrated.model

    @property
    def params(self) -> Float:
        return self.calibrated.params

    @property
    def std(self) -> Float:
        return self.calibrated.std

    def correlation(self) -> Float:
        return correlation_from_covariance(self.covariance)


def _joint_range(meas: Measurements, robot: RobotDescription) -> list[list[float]]:
    """The joint ranges of the calibration data as a model file keeps them: ``[lo, hi]``
    per joint in deg (mm for prismatic joints); evaluate and compensate warn beyond them
    (:func:`kinecal.io.extrapolation`)."""
    scale = np.where(robot.prismatic, 1e3, 180.0 / np.pi)
    lo, hi = meas.q_ctrl.min(axis=0) * scale, meas.q_ctrl.max(axis=0) * scale
    return [
        [round(float(a), 6), round(float(b), 6)] for a, b in zip(lo, hi, strict=True)
    ]
