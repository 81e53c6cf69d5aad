"""Plan a calibration measurement: choose, order and assess n of N candidate poses.

:func:`plan_poses` builds the design problem at the planning model's design point
(:mod:`._design`), selects the poses (:mod:`._exchange`), orders them for short joint
motion (:mod:`._order`) and predicts the parameter standard deviations and the held-out
accuracy, for the plan and for random plans of the same size (:mod:`._predict`).

A sequential plan adds poses to an existing calibration: the information of the poses
measured before (or, without them, the calibrated standard deviations) is the starting
point, and the new poses go where the model's prediction is least certain.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from kinecal._blas import one_blas_thread
from kinecal.models import CalibrationModel, ModelInputs
from kinecal.planning._design import DesignProblem, design_problem
from kinecal.planning._exchange import Selection, select_poses
from kinecal.planning._order import path_length, tour
from kinecal.planning._predict import (
    Prediction,
    RandomPrediction,
    predict,
    predict_random,
)
from kinecal.planning._setup import Instrument, candidate_inputs
from kinecal.typing import Float

__all__ = ["Plan", "plan_poses"]

log = logging.getLogger(__name__)

_GENERIC = 1e-4  # lambda* of the design point [rad/m] (see _design)


@dataclass
class Plan:
    """A measurement plan.

    Attributes
    ----------
    index : (n,) chosen candidates (indices into the candidates), in measuring order.
    q_ctrl : (n, J) their controller angles [rad], in measuring order.
    target_index : (n,) int or None, the target each sensor pose looks at.
    selection : Selection (the search: criterion, values, swaps, time).
    problem : DesignProblem (over the candidates, then any poses measured before).
    planned : Prediction of the plan.
    random : RandomPrediction of random plans of the same size.
    before : Prediction with the poses measured before only (sequential plans).
    path : largest joint motion summed along the measuring order [rad].
    path_unordered : the same in the order the poses were chosen [rad].
    warnings : list of str
    """

    index: np.ndarray
    q_ctrl: Float
    target_index: np.ndarray | None
    selection: Selection
    problem: DesignProblem
    planned: Prediction
    random: RandomPrediction
    before: Prediction | None = None
    path: float = 0.0
    path_unordered: float = 0.0
    warnings: list[str] = field(default_factory=list)


@one_blas_thread()
def plan_poses(
    model: CalibrationModel,
    params: Float,
    q_candidates: Float,
    n: int,
    instrument: Instrument | None = None,
    *,
    criterion: str = "I",
    exchange: str = "fedorov",
    priors: str = "all",
    target_index: np.ndarray | None = None,
    calibrated: bool = False,
    measured: Float | None = None,
    measured_target_index: np.ndarray | None = None,
    calibrated_std: Float | None = None,
    random_draws: int = 20,
    seed: int = 0,
    home: Float | None = None,
) -> Plan:
    """Choose ``n`` of the candidate poses that determine ``model`` best.

    Parameters
    ----------
    model : CalibrationModel (its spec fitted to the instrument, as
        :func:`kinecal.planning.planning_model` makes it).
    params : (P,) nominal parameters with the set-up's user frame and tool (SI); or a
        calibrated model's parameters with ``calibrated=True``.
    q_candidates : (N, J) candidate controller angles [rad].
    n : poses to choose.
    instrument : Instrument (default: a laser tracker with 0.01 mm noise).
    criterion : 'I' (average prediction variance, default), 'D', 'A', 'E' or 'G'.
    exchange : 'fedorov' (default), 'detmax' or 'none'.
    priors : the calibration's priors ('all', 'compliance', 'none').
    target_index : (N,) int, optional, the target of each sensor candidate.
    calibrated : evaluate at ``params`` as they are (compliance terms included) instead of
        at generic compliance values.
    measured : (M, J), optional, poses measured before (sequential design).
    measured_target_index : (M,) int, their targets (sensor).
    calibrated_std : (P,), optional
        Standard deviations of a calibration (SI; NaN where not estimated), used as
        independent information when ``measured`` is not given.
    random_draws : random plans averaged for the comparison.
    seed : seed of the random plans.
    home : (J,) the robot's pose before the first measurement [rad] (default zeros).
    """
    inst = instrument or Instrument()
    qc = np.asarray(q_candidates, np.float64)
    N = qc.shape[0]
    if not 1 <= n <= N:
        raise ValueError(
            f"the number of poses must be between 1 and {N} (the candidates); got {n}."
        )
    inputs, ti = candidate_inputs(model, params, qc, inst, target_index)
    all_inputs, n_meas = _with_measured(
        model, params, qc, inputs, inst, measured, measured_target_index
    )
    weight = np.concatenate([np.full(N, 1.0 / N), np.zeros(n_meas)])
    pb = design_problem(
        model,
        params,
        all_inputs,
        inst.noise,
        sigma_rot=inst.noise_rot if inst.kind == "pose" else None,
        priors=priors,
        compliance=None if calibrated else _GENERIC,
        weight=weight,
    )
    warnings: list[str] = []
    base, exclude = _information_before(pb, N, n_meas, calibrated_std, warnings)
    m_res = (n + n_meas) * pb.rows
    if m_res < 2 * pb.size:
        warnings.append(_few_poses(n + n_meas, pb))
    sel = select_poses(
        pb, n, criterion=criterion, exchange=exchange, base=base, exclude=exclude
    )
    chosen = sel.index
    planned = predict(pb, pb.information(chosen, base), n)
    rand = predict_random(
        pb, n, draws=random_draws, seed=seed, base=base, exclude=exclude
    )
    before = None if base is None else predict(pb, base, 0)
    order = tour(qc[chosen], home)
    idx = chosen[order]
    dropped = [d.name for d in pb.identifiability.dropped]
    if dropped:
        log.info("not determined by any candidate (fixed): %s", ", ".join(dropped))
    return Plan(
        index=idx,
        q_ctrl=qc[idx],
        target_index=None if ti is None else ti[idx],
        selection=sel,
        problem=pb,
        planned=planned,
        random=rand,
        before=before,
        path=path_length(qc[idx]),
        path_unordered=path_length(qc[chosen]),
        warnings=warnings,
    )


def _with_measured(
    model: CalibrationModel,
    params: Float,
    qc: Float,
    inputs: ModelInputs,
    inst: Instrument,
    measured: Float | None,
    measured_target_index: np.ndarray | None,
) -> tuple[ModelInputs, int]:
    """``(inputs of the candidates then the poses measured before, how many of
    those)``."""
    if measured is None:
        return inputs, 0
    qm = np.asarray(measured, np.float64)
    inp_m, _ = candidate_inputs(model, params, qm, inst, measured_target_index)
    all_inputs = ModelInputs.make(
        np.concatenate([qc, qm]), p_cam=np.concatenate([inputs.p_cam, inp_m.p_cam])
    )
    return all_inputs, qm.shape[0]


def _few_poses(poses: int, pb: DesignProblem) -> str:
    """The warning for ``poses`` too few for the first, unconstrained stage."""
    m_res = poses * pb.rows
    return (
        f"{poses} poses give {m_res} residuals for {pb.size} parameters: the "
        "calibration's first, unconstrained stage is poorly determined by so few, "
        "and the result can fall far short of the prediction; plan at least "
        f"{-(-2 * pb.size // pb.rows)} poses."
    )


def _information_before(
    pb: DesignProblem,
    N: int,
    n_meas: int,
    calibrated_std: Float | None,
    warnings: list[str],
) -> tuple[Float | None, np.ndarray | None]:
    """``(information of what is known before, candidates excluded)``: the ``n_meas``
    poses measured before (rows after the ``N`` candidates), else a calibration's
    standard deviations (a warning appended), else nothing."""
    if n_meas:
        return pb.information(np.arange(N, N + n_meas)), np.arange(N + n_meas) >= N
    if calibrated_std is None:
        return None, None
    std = np.asarray(calibrated_std, np.float64)[pb.free]
    known = np.isfinite(std) & (std > 0)
    prec = pb.prior_precision.copy()
    # at least the prior's (a std of 1e300: no information, a singular matrix)
    prec[known] = np.maximum(prec[known], (pb.scales[known] / std[known]) ** 2)
    if not known.any():  # std null throughout (a fit without covariance)
        warnings.append(
            "without the poses measured before, and without standard deviations in "
            "the model file (std: null), nothing is known of them: planned as for a "
            "new calibration."
        )
        return None, None
    warnings.append(
        "without the poses measured before, their information is taken from the "
        "calibrated standard deviations alone (correlations ignored)."
    )
    return np.diag(prec), None
