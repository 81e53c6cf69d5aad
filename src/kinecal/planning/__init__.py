"""Pose planning: choose the poses that determine a calibration model best (issue 22).

The design problem (:mod:`._design`) holds every candidate pose's information about the
model's parameters at a design point, with the calibration's priors; the exchange
algorithms (:mod:`._exchange`) choose the poses that optimise a criterion
(:mod:`._criteria`: I-, D-, A-, E-, G-optimal); :mod:`._order` orders them for short
joint motion and :mod:`._predict` says what accuracy to expect. :func:`plan_poses` does
all of it; :mod:`._candidates` makes candidates when the user has none.
"""

from kinecal.planning._candidates import (
    Candidates,
    halton,
    joint_candidates,
    sensor_candidates,
)
from kinecal.planning._criteria import CRITERIA, DesignState
from kinecal.planning._design import (
    DesignProblem,
    design_point,
    design_problem,
    prior_sigma,
)
from kinecal.planning._exchange import EXCHANGES, Selection, select_poses
from kinecal.planning._order import path_length, tour
from kinecal.planning._plan import Plan, plan_poses
from kinecal.planning._predict import (
    Prediction,
    RandomPrediction,
    predict,
    predict_random,
)
from kinecal.planning._setup import (
    INSTRUMENTS,
    Instrument,
    candidate_inputs,
    planning_model,
)

__all__ = [
    "CRITERIA",
    "EXCHANGES",
    "INSTRUMENTS",
    "Candidates",
    "DesignProblem",
    "DesignState",
    "Instrument",
    "Plan",
    "Prediction",
    "RandomPrediction",
    "Selection",
    "candidate_inputs",
    "design_point",
    "design_problem",
    "halton",
    "joint_candidates",
    "path_length",
    "plan_poses",
    "planning_model",
    "predict",
    "predict_random",
    "prior_sigma",
    "select_poses",
    "sensor_candidates",
    "tour",
]
