"""Is the nominal robot right, and do the priors hold the fit back? (issue 20, point 4)

A calibration starts from the nominal table and its priors pull every joint-geometry term
towards it (MAP, Eq. (T-5)). Two findings, both from a second fit without the priors of
the joint geometry and the frames (``--priors compliance``: the transmission and
compliance terms keep theirs, which say nothing of the nominal table and keep their
weakly determined combinations from wandering) run on the fly:

* ``priors_held``: the fit with priors leaves residuals clearly larger, relative to the
  noise, than the fit without, ``s0_MAP / s0_LS > 1.5`` (``s0``: a-posteriori standard
  deviation of unit weight, each on its own noise estimate; with a right nominal and
  right priors the two agree within a few percent). The parameters named are those the
  priors hold far from where the data put them: at least two prior standard deviations
  from nominal with priors, and further still without;
* ``nominal_mismatch``: on top of that, or when the joint-geometry priors had to be
  widened beyond 5 mm or 5 deg to let the data through, the nominal robot with fitted frames
  leaves errors far above the calibrated noise: a nominal table of another robot (a UR10
  table for a UR10e), or a robot file in the wrong units.

The cost is one more calibration, on the rows the first one kept, without its rejection,
evidence scaling or diagnosis (without any priors the full model's stage 3 took 94
iterations and 1 s on 2000 poses; with the compliance priors kept, 0.07 s, and 0.03 s
without those three stages). It shares the calibration's registration and identifiability
analysis, and starts from the calibration's solution; only where that fit finds the priors
holding the calibration back (its noise ratio above 1.2) does the fit from nominal run,
and its numbers are the ones reported (issue 36: 9 -> 3 Jacobian passes on 2000 twin poses,
the findings unchanged; then 2 -> 1: that fit reads only its s0, so it stops on the
pre-fits' tolerance and takes no Jacobian at its solution, :data:`SCREEN_FIT`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal._record import Record
from kinecal.identification._calibrate import (
    CalibrationResult,
    build_prior,
    calibrate,
    calibrate_problem,
    default_stages,
)
from kinecal.identification._diagnose import Diagnose
from kinecal.identification._noise import estimate_noise
from kinecal.identification._options import CalibrationOptions
from kinecal.identification._priors import EvidencePriors
from kinecal.identification._problem import Problem, State
from kinecal.identification._robust import RobustRejection
from kinecal.identification._stages import (
    FullStage,
    Identify,
    KinematicStage,
    Register,
    TransmissionStage,
)
from kinecal.identification._uncertainty import Uncertainty
from kinecal.measurement._diagnostics import Diagnostic
from kinecal.measurement._measurements import Measurements
from kinecal.models import KINDS
from kinecal.robot import RobotDescription
from kinecal.typing import Float

__all__ = ["nominal_check"]

# The priors fight the data when the residuals with them exceed, relative to the noise,
# those without by this factor.
HELD_RATIO = 1.5
# The fit from the calibration's solution answers alone below this ratio (a margin under
# HELD_RATIO: the fit from nominal, run above it, could end in a lower minimum).
SCREEN_RATIO = 1.2
# A prior sits at this many of its standard deviations: the data pull hard against it.
HELD_PULL = 2.0
# Joint-geometry priors widened (adapt_priors) beyond these: far from nominal. Lengths
# beyond 5x their default (5 mm); angles beyond 5 deg (joint zero offsets of a degree or
# two are common, an axis turned the wrong way is not).
WIDE_FACTOR = 5.0
WIDE_ANGLE_DEG = 5.0
# The nominal robot with fitted frames leaves errors this many times the calibrated ones.
FAR_FACTOR = 2.0
_STAGE = "nominal check"
# The screen's stage 3: its s0 alone is read, so it stops on the pre-fits' tolerance
# and takes no Jacobian at its solution (issue 36: one Jacobian pass fewer).
SCREEN_FIT = FullStage(screen=True)


@dataclass(frozen=True, eq=False, repr=False)
class _FromFit(Record):
    """The nominal check's start: the calibration's solution, with the noise its
    residuals give (pose data without sigmas), for stage 3 without the geometry priors;
    for a model with only kinematic terms, stage 1 from there (stage 3 has nothing to
    add)."""

    x: Float
    name: str = "nominal check: from the fit"

    def __call__(self, problem: Problem, state: State) -> State:
        state = state.but(x=self.x.copy())
        kin = problem.kinematic
        if problem.estimate_noise:
            state = estimate_noise(
                problem, state, state.x, state.free, state.active_prior()
            )
        if np.any(state.free & ~kin):
            return state
        return KinematicStage()(problem, state)


def _without_geometry_priors(
    result: CalibrationResult,
    robot: RobotDescription,
    meas: Measurements,
    opts: CalibrationOptions,
    *,
    from_fit: bool = False,
) -> CalibrationResult | None:
    """The calibration again without the geometry priors (``--priors compliance``), on
    the rows it kept (its gross errors are not the nominal's fault), with its own noise
    estimate: each fit's ``s0`` is relative to the noise its own residuals give.

    (A refit from the calibration's solution with its weights was tried: on the UR10e
    mocap poses with the CB table its ``s0`` stays that of the calibration, 2.96, where
    the fit with its own noise gives 0.99; the finding rests on that difference.)

    Registration and the identifiability analysis depend on neither the priors nor the
    rejection: on the same rows the calibration's own state after them serves
    (:attr:`CalibrationResult.identified`; the same numbers). With ``from_fit`` the fit
    starts from the calibration's solution, with the noise its residuals give, instead
    of stages 1 and 2 from nominal (1 Jacobian pass with the calibration's workspace
    instead of 7 on 2000 twin poses); None where there is no shared state. On data far
    from nominal it can end in another minimum than the fit from nominal (the UR10e
    poses on the CB table: RMS 2.66 against 2.79 mm), so :func:`nominal_check` uses it
    only to screen.
    """
    free = replace(opts, priors="compliance", reject="off")
    kept = ~np.isin(meas.rows, [o.row for o in result.rejected])
    data = meas if kept.all() else meas.subset(kept)
    # What the check reads is the fit, its s0 and its standard deviations: no evidence
    # scaling of the compliance priors (it moves s0 by a percent or two, against a
    # threshold of 50 %) and no diagnosis (a fifth of the cost).
    stages = [
        s
        for s in default_stages(free)
        if not isinstance(s, (EvidencePriors, RobustRejection, Diagnose))
    ]
    start = result.identified
    shared = (
        start is not None
        and start.active is None
        and kept.all()
        and isinstance(stages[0], Register)
        and isinstance(stages[1], Identify)
        and np.array_equal(start.free, result.identifiability.free)
    )
    if not shared:
        return (
            None
            if from_fit
            else calibrate(robot, data, result.model.spec, free, stages=stages)
        )
    rest = stages[2:]
    if from_fit:
        # The screen answers alone only below SCREEN_RATIO < HELD_RATIO, where the
        # findings read its s0 and its parameters, never its standard deviations: no
        # covariance (its jackknife alone was a third of the screen's cost), and a
        # stage 3 that stops as the pre-fits do (SCREEN_FIT: s0 moves by ~1e-6).
        rest = [
            Uncertainty(covariance=False)
            if isinstance(s, Uncertainty)
            else SCREEN_FIT
            if isinstance(s, FullStage)
            else s
            for s in rest
            if not isinstance(s, (KinematicStage, TransmissionStage))
        ]
        at = rest.index(next(s for s in rest if isinstance(s, FullStage)))
        rest.insert(at, _FromFit(result.params))
    # On the calibration's own rows, with its workspace: the points it evaluated (its
    # solution, where the fit from it starts) are served from there.
    ws = result.workspace.copy() if result.workspace is not None else None
    problem = Problem.make(robot, data, result.model.spec, free, workspace=ws)
    return calibrate_problem(problem, rest, start)


@one_blas_thread()
def nominal_check(
    result: CalibrationResult,
    robot: RobotDescription,
    meas: Measurements,
    *,
    options: CalibrationOptions | None = None,
    unconstrained: CalibrationResult | None = None,
) -> list[Diagnostic]:
    """Compare a calibration with its nominal robot and with a fit without the geometry
    priors.

    Parameters
    ----------
    result : the calibration to check (``calibrate(robot, meas, spec, options)``).
    robot, meas : what it was calibrated from.
    options : the options it was calibrated with (default :class:`CalibrationOptions`).
    unconstrained : the same calibration with ``priors='compliance'``, if already done;
        otherwise it is run here.

    Returns
    -------
    list of Diagnostic
        ``priors_held`` (parameters: those held) and ``nominal_mismatch``; empty when the
        nominal robot and the priors agree with the data.
    """
    opts = options or CalibrationOptions()
    if opts.priors != "all" or result.prior is None:
        return []  # no geometry priors: nothing held; the fit is the unconstrained one
    ls = unconstrained
    if ls is None:
        # A fit from the calibration's solution first: where it leaves the residuals
        # well within HELD_RATIO of the calibration's, nothing is held and it is the
        # answer; otherwise the fit from nominal, whose numbers the findings report.
        ls = _without_geometry_priors(result, robot, meas, opts, from_fit=True)
        if ls is None or result.sigma0 > SCREEN_RATIO * ls.sigma0:
            ls = _without_geometry_priors(result, robot, meas, opts)
    assert ls is not None
    est = np.array(
        [
            a == "estimated" == b
            for a, b in zip(result.calibrated.status, ls.calibrated.status)
        ]
    )
    out: list[Diagnostic] = []
    held: list[str] = []
    if result.sigma0 / max(ls.sigma0, 1e-12) > HELD_RATIO:
        held, found = _priors_held(result, ls, est)
        out.append(found)
    default = build_prior(result.model, result.registered, opts).sigma
    mismatch = _nominal_mismatch(result, robot, est, default, held)
    return out + ([mismatch] if mismatch is not None else [])


def _priors_held(
    result: CalibrationResult, ls: CalibrationResult, est: np.ndarray
) -> tuple[list[str], Diagnostic]:
    """``priors_held``: the parameters the priors hold at least :data:`HELD_PULL` of
    their sigmas from nominal, which the fit without them (``ls``) puts further still
    the same way, and the finding."""
    assert result.prior is not None
    names = result.model.layout.names
    x0, sigma = result.registered, result.prior.sigma
    ratio = result.sigma0 / max(ls.sigma0, 1e-12)
    pull = np.where(np.isfinite(sigma) & est, np.abs(result.params - x0) / sigma, 0.0)
    # ... and the data, without its prior, put it further still the same way.
    d_map, d_ls = result.params - x0, ls.params - x0
    further = (np.sign(d_ls) == np.sign(d_map)) & (np.abs(d_ls) > np.abs(d_map))
    order = np.argsort(-pull)
    held = [names[i] for i in order if pull[i] >= HELD_PULL and further[i]]
    parts = []
    for i in (names.index(n) for n in held[:4]):
        kind = KINDS[result.model.layout.specs[i].kind]
        f, unit = kind.to_file, kind.file_unit
        parts.append(
            f"{names[i]} {(result.params[i] - x0[i]) * f:+.3g} {unit} from nominal "
            f"(prior {sigma[i] * f:.3g} {unit}; {(ls.params[i] - x0[i]) * f:+.3g} ± "
            f"{ls.std[i] * f:.2g} {unit} without)"
        )
    return held, Diagnostic(
        "priors_held",
        f"the priors hold the fit back: it leaves {ratio:.2f}x the residuals "
        "(relative to the noise) of a fit without the geometry priors "
        "(--priors compliance: RMS "
        f"{ls.metrics_after.rms_mm:.4g} mm against {result.metrics_after.rms_mm:.4g} "
        "mm)"
        + (f"; held: {'; '.join(parts)}" if parts else "")
        + ". The nominal values are likely wrong: check the robot model "
        "(version, e-Series or CB) and the robot file, or calibrate with "
        "--priors compliance.",
        parameters=tuple(held),
        stage=_STAGE,
    )


def _nominal_mismatch(
    result: CalibrationResult,
    robot: RobotDescription,
    est: np.ndarray,
    default: Float,
    held: list[str],
) -> Diagnostic | None:
    """``nominal_mismatch``: parameters held, or joint-geometry priors widened beyond
    :data:`WIDE_FACTOR` times their ``default`` (lengths) or :data:`WIDE_ANGLE_DEG`,
    while the nominal robot with fitted frames leaves :data:`FAR_FACTOR` times the
    calibrated errors."""
    assert result.prior is not None
    names, sigma = result.model.layout.names, result.prior.sigma
    specs = result.model.layout.specs
    limit = np.array(
        [
            WIDE_FACTOR * default[i]
            if sp.kind == "length"
            else np.radians(WIDE_ANGLE_DEG)
            if sp.kind == "angle"
            else np.inf
            for i, sp in enumerate(specs)
        ]
    )
    joint = np.array([sp.group == "joint" for sp in specs])
    widened = joint & est & np.isfinite(sigma) & np.isfinite(default) & (sigma > limit)
    before, after = result.metrics_before.rms_mm, result.metrics_after.rms_mm
    if not ((held or widened.any()) and before > FAR_FACTOR * after):
        return None
    wide = [names[i] for i in np.flatnonzero(widened)]
    because = (
        "the data put the joint geometry far from nominal (priors widened beyond "
        f"{WIDE_FACTOR:g} mm or {WIDE_ANGLE_DEG:g} deg) for "
        + ", ".join(wide[:4])
        + (" ..." if len(wide) > 4 else "")
        if wide and not held
        else "the priors hold parameters far from where the data put them"
    )
    return Diagnostic(
        "nominal_mismatch",
        f"the nominal {robot.name} with fitted frames leaves {before:.4g} mm RMS, "
        f"{before / max(after, 1e-12):.1f}x the calibrated {after:.4g} mm, and "
        f"{because}: a nominal table of another robot (or version), or a robot "
        "file in the wrong units?",
        parameters=tuple(held or wide),
        stage=_STAGE,
    )
