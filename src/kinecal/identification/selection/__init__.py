"""Model selection and cross-validation, on top of the fitter.

Which terms the data support, and how well a calibration predicts poses it was not
fitted on: the folds (:func:`make_folds`: random poses, regions of the workspace, whole
sessions or the user's groups), k-fold cross-validation and the model comparison of the
paper's Tables 5 and 8 (``_crossval``), ``--model auto`` (:func:`select_model`: the
candidates' fits from one shared fit, ``_candidates``; each fold's fit from its
candidate's, ``_foldfit``; the one-standard-error rule, ``_rule``) and the held-out
figures of ``--cv`` (:func:`held_out_accuracy`, ``_heldout``).

The package sits above the fitter: it calibrates and evaluates through the fitter's
public helpers (the names in the ``__all__`` of :mod:`kinecal.identification`'s
modules), and nothing of the fitter imports it. :mod:`kinecal.identification`
re-exports every name here unchanged.

Each name loads its module on first use (:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
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

__all__ = [
    "Candidate",
    "ComparisonRow",
    "CrossValidation",
    "Folds",
    "HeldOutAccuracy",
    "HeldOutFigure",
    "Selection",
    "candidate_specs",
    "compare_models",
    "cross_validate",
    "cross_validate_many",
    "cross_validate_models",
    "held_out_accuracy",
    "kfold_indices",
    "make_folds",
    "pose_features",
    "region_labels",
    "select_model",
    "train_test_split",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_crossval": (
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
        "_heldout": ("HeldOutAccuracy", "HeldOutFigure", "held_out_accuracy"),
        "_select": (
            "Candidate",
            "Selection",
            "candidate_specs",
            "cross_validate_models",
            "select_model",
        ),
    },
)
