"""Typed workflows: what a ``kinecal`` command does, as one function a Python user can call.

The command line parses options, checks its arguments, calls the workflow and writes and
prints its result; the workflow does the work and returns a frozen result. Each name
loads its module on first use (:mod:`kinecal._lazy`); docs/workflows.md shows each one.

>>> from kinecal.io import read_measurements                     # doctest: +SKIP
>>> from kinecal.robot import load_robot
>>> from kinecal.workflows import calibrate_measurements
>>> robot = load_robot("fanuc-lrmate200id")
>>> run = calibrate_measurements(robot, read_measurements("train.csv", robot), cv_folds=5)
>>> run.spec.name, run.held_out.transfer.model.rms_mm
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.workflows._calibrate import (
        CalibrationRun,
        calibrate_measurements,
    )
    from kinecal.workflows._export import (
        ModelExport,
        export_model,
    )
    from kinecal.workflows._fk import (
        ImportedRobot,
        PoseReport,
        forward_pose,
        import_urdf_robot,
    )

__all__ = [
    "CalibrationRun",
    "ImportedRobot",
    "ModelExport",
    "PoseReport",
    "calibrate_measurements",
    "export_model",
    "forward_pose",
    "import_urdf_robot",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_calibrate": (
            "CalibrationRun",
            "calibrate_measurements",
        ),
        "_export": (
            "ModelExport",
            "export_model",
        ),
        "_fk": (
            "ImportedRobot",
            "PoseReport",
            "forward_pose",
            "import_urdf_robot",
        ),
    },
)
