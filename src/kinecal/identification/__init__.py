"""Identification: residuals, LM solver, three stages (Sec. 4), identifiability, metrics."""

from kinecal.identification._calibrate import (
    PRIOR_SIGMA,
    CalibrationOptions,
    CalibrationResult,
    Outlier,
    StageLog,
    calibrate,
    spec_for,
)
from kinecal.identification._calibrated import STATUSES, CalibratedModel
from kinecal.identification._evaluate import (
    ComparisonRow,
    CrossValidation,
    Evaluation,
    compare_models,
    cross_validate,
    cross_validate_many,
    evaluate,
    kfold_indices,
    refit,
    registered_model,
    train_test_split,
)
from kinecal.identification._identifiability import (
    DroppedParameter,
    Identifiability,
    analyse_identifiability,
    correlation_from_covariance,
    priority_order,
)
from kinecal.identification._init import initial_frames
from kinecal.identification._lm import (
    LMOptions,
    LMResult,
    normal_equations,
    solve_fixed_step,
    solve_lm,
)
from kinecal.identification._measurements import KINDS, Measurements
from kinecal.identification._metrics import Metrics, metrics_from_errors
from kinecal.identification._residuals import ResidualBlock, Weights, residuals
from kinecal.identification._select import (
    Candidate,
    Selection,
    candidate_specs,
    select_model,
)

__all__ = [
    "KINDS",
    "PRIOR_SIGMA",
    "STATUSES",
    "CalibratedModel",
    "CalibrationOptions",
    "CalibrationResult",
    "Candidate",
    "ComparisonRow",
    "CrossValidation",
    "DroppedParameter",
    "Evaluation",
    "Identifiability",
    "LMOptions",
    "LMResult",
    "Measurements",
    "Metrics",
    "Outlier",
    "ResidualBlock",
    "Selection",
    "StageLog",
    "Weights",
    "analyse_identifiability",
    "calibrate",
    "candidate_specs",
    "compare_models",
    "correlation_from_covariance",
    "cross_validate",
    "cross_validate_many",
    "evaluate",
    "initial_frames",
    "kfold_indices",
    "metrics_from_errors",
    "normal_equations",
    "priority_order",
    "refit",
    "registered_model",
    "residuals",
    "select_model",
    "solve_fixed_step",
    "solve_lm",
    "spec_for",
    "train_test_split",
]
