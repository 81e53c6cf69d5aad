"""ISO 9283 pose accuracy and repeatability (ISO 9283:1998, 6.2, 7.2 and 7.4).

The test cube and its five points (:class:`IsoCube`), the test program by inverse
kinematics (:func:`iso_plan`, :func:`plan_iso9283`), the standard's characteristics
(:func:`pose_characteristics`: AP, RP per point; :func:`distance_characteristics`: AD, RD)
and the evaluation of measured cycles with a calibrated model and with the nominal robot
(:func:`evaluate_iso9283`); the program compensated with a calibrated model
(:func:`compensated_plan`) for the test after compensation. Definitions and how they
differ from RMS: docs/iso9283.md. Each name loads its module on first use
(:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.iso9283._characteristics import (
        DistanceFigures,
        PointFigures,
        distance_characteristics,
        orientation_abc,
        pose_characteristics,
    )
    from kinecal.iso9283._compensate import compensated_plan, user_from_base
    from kinecal.iso9283._cube import (
        PLANES,
        POINT_LABELS,
        VISIT_ORDER,
        IsoCube,
        iso_cube,
    )
    from kinecal.iso9283._evaluate import (
        IsoEvaluation,
        IsoFigures,
        evaluate_iso9283,
        nominal_placed,
    )
    from kinecal.iso9283._plan import (
        DEFAULT_CYCLES,
        IsoPlan,
        iso_plan,
        nominal_model,
        place_cube,
        plan_iso9283,
    )

__all__ = [
    "DEFAULT_CYCLES",
    "PLANES",
    "POINT_LABELS",
    "VISIT_ORDER",
    "DistanceFigures",
    "IsoCube",
    "IsoEvaluation",
    "IsoFigures",
    "IsoPlan",
    "PointFigures",
    "compensated_plan",
    "distance_characteristics",
    "evaluate_iso9283",
    "iso_cube",
    "iso_plan",
    "nominal_model",
    "nominal_placed",
    "orientation_abc",
    "place_cube",
    "plan_iso9283",
    "pose_characteristics",
    "user_from_base",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_characteristics": (
            "DistanceFigures",
            "PointFigures",
            "distance_characteristics",
            "orientation_abc",
            "pose_characteristics",
        ),
        "_compensate": ("compensated_plan", "user_from_base"),
        "_cube": ("PLANES", "POINT_LABELS", "VISIT_ORDER", "IsoCube", "iso_cube"),
        "_evaluate": (
            "IsoEvaluation",
            "IsoFigures",
            "evaluate_iso9283",
            "nominal_placed",
        ),
        "_plan": (
            "DEFAULT_CYCLES",
            "IsoPlan",
            "iso_plan",
            "nominal_model",
            "place_cube",
            "plan_iso9283",
        ),
    },
)
