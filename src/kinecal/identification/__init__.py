"""Identification: residuals, LM solver, stages (Sec. 4, Fig. 6), identifiability, metrics;
model selection and cross-validation (:mod:`kinecal.identification.selection`, whose
names are re-exported here).

Each name loads its module on first use (:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.identification._calibrate import (
        CalibrationResult,
        calibrate,
        default_stages,
    )
    from kinecal.identification._diagnose import Diagnose
    from kinecal.identification._evaluate import (
        Evaluation,
        evaluate,
        refit,
        refit_diagnosed,
        registered_model,
    )
    from kinecal.identification._fixed_step import solve_fixed_step
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
        solve_lm,
    )
    from kinecal.identification._noise import NoiseModel
    from kinecal.identification._nominal_check import nominal_check
    from kinecal.identification._options import (
        PRIOR_SIGMA,
        CalibrationOptions,
        FitSettings,
        IdentifySettings,
        PriorSettings,
        RejectSettings,
        Tuning,
    )
    from kinecal.identification._priors import EvidencePriors, Priors, build_prior
    from kinecal.identification._problem import (
        EvaluationCache,
        Problem,
        Stage,
        State,
        run_stages,
        spec_for,
    )
    from kinecal.identification._registration import (
        Registration,
        initial_registration,
        register,
    )
    from kinecal.identification._robust import RobustRejection
    from kinecal.identification._stages import (
        FullStage,
        Identify,
        KinematicStage,
        Register,
        TransmissionStage,
    )
    from kinecal.identification._uncertainty import Uncertainty
    from kinecal.identification.selection._crossval import (
        ComparisonRow,
        CrossValidation,
        Folds,
        compare_models,
        cross_validate,
        cross_validate_many,
        kfold_indices,
        make_folds,
        pose_features,
        region_labels,
        train_test_split,
    )
    from kinecal.identification.selection._heldout import (
        HeldOutAccuracy,
        HeldOutFigure,
        held_out_accuracy,
    )
    from kinecal.identification.selection._select import (
        Candidate,
        Selection,
        candidate_specs,
        cross_validate_models,
        select_model,
    )
    from kinecal.measurement._calibrated import STATUSES, CalibratedModel
    from kinecal.measurement._diagnostics import CODES, Diagnostic, Outlier, StageLog
    from kinecal.measurement._measurements import KINDS, Measurements
    from kinecal.measurement._metrics import Metrics, metrics_from_errors
    from kinecal.measurement._residuals import ResidualBlock, Weights, residuals

__all__ = [
    "CODES",
    "KINDS",
    "PRIOR_SIGMA",
    "STATUSES",
    "CalibratedModel",
    "CalibrationOptions",
    "CalibrationResult",
    "Candidate",
    "ComparisonRow",
    "CrossValidation",
    "Diagnose",
    "Diagnostic",
    "DroppedParameter",
    "Evaluation",
    "EvaluationCache",
    "EvidencePriors",
    "FitSettings",
    "Folds",
    "FullStage",
    "HeldOutAccuracy",
    "HeldOutFigure",
    "Identifiability",
    "Identify",
    "IdentifySettings",
    "KinematicStage",
    "LMOptions",
    "LMResult",
    "Measurements",
    "Metrics",
    "NoiseModel",
    "Outlier",
    "PriorSettings",
    "Priors",
    "Problem",
    "Register",
    "Registration",
    "RejectSettings",
    "ResidualBlock",
    "RobustRejection",
    "Selection",
    "Stage",
    "StageLog",
    "State",
    "TransmissionStage",
    "Tuning",
    "Uncertainty",
    "Weights",
    "analyse_identifiability",
    "build_prior",
    "calibrate",
    "candidate_specs",
    "compare_models",
    "correlation_from_covariance",
    "cross_validate",
    "cross_validate_many",
    "cross_validate_models",
    "default_stages",
    "evaluate",
    "held_out_accuracy",
    "initial_frames",
    "initial_registration",
    "kfold_indices",
    "make_folds",
    "metrics_from_errors",
    "nominal_check",
    "normal_equations",
    "pose_features",
    "priority_order",
    "refit",
    "refit_diagnosed",
    "region_labels",
    "register",
    "registered_model",
    "residuals",
    "run_stages",
    "select_model",
    "solve_fixed_step",
    "solve_lm",
    "spec_for",
    "train_test_split",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_calibrate": (
            "CalibrationResult",
            "calibrate",
            "default_stages",
        ),
        "kinecal.measurement._calibrated": (
            "STATUSES",
            "CalibratedModel",
        ),
        "kinecal.identification.selection._crossval": (
            "ComparisonRow",
            "CrossValidation",
            "Folds",
            "compare_models",
            "cross_validate",
            "cross_validate_many",
            "kfold_indices",
            "make_folds",
            "pose_features",
            "region_labels",
            "train_test_split",
        ),
        "_diagnose": ("Diagnose",),
        "kinecal.measurement._diagnostics": (
            "CODES",
            "Diagnostic",
            "Outlier",
            "StageLog",
        ),
        "_evaluate": (
            "Evaluation",
            "evaluate",
            "refit",
            "refit_diagnosed",
            "registered_model",
        ),
        "kinecal.identification.selection._heldout": (
            "HeldOutAccuracy",
            "HeldOutFigure",
            "held_out_accuracy",
        ),
        "_identifiability": (
            "DroppedParameter",
            "Identifiability",
            "analyse_identifiability",
            "correlation_from_covariance",
            "priority_order",
        ),
        "_init": ("initial_frames",),
        "_fixed_step": ("solve_fixed_step",),
        "_lm": (
            "LMOptions",
            "LMResult",
            "normal_equations",
            "solve_lm",
        ),
        "kinecal.measurement._measurements": (
            "KINDS",
            "Measurements",
        ),
        "kinecal.measurement._metrics": (
            "Metrics",
            "metrics_from_errors",
        ),
        "_noise": ("NoiseModel",),
        "_nominal_check": ("nominal_check",),
        "_options": (
            "PRIOR_SIGMA",
            "CalibrationOptions",
            "FitSettings",
            "IdentifySettings",
            "PriorSettings",
            "RejectSettings",
            "Tuning",
        ),
        "_priors": (
            "EvidencePriors",
            "Priors",
            "build_prior",
        ),
        "_problem": (
            "EvaluationCache",
            "Problem",
            "Stage",
            "State",
            "run_stages",
            "spec_for",
        ),
        "_registration": (
            "Registration",
            "initial_registration",
            "register",
        ),
        "kinecal.measurement._residuals": (
            "ResidualBlock",
            "Weights",
            "residuals",
        ),
        "_robust": ("RobustRejection",),
        "kinecal.identification.selection._select": (
            "Candidate",
            "Selection",
            "candidate_specs",
            "cross_validate_models",
            "select_model",
        ),
        "_stages": (
            "FullStage",
            "Identify",
            "KinematicStage",
            "Register",
            "TransmissionStage",
        ),
        "_uncertainty": ("Uncertainty",),
    },
)
