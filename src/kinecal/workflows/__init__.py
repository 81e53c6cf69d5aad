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
    from kinecal.demo import (
        DemoRun,
        paper_demo,
    )
    from kinecal.workflows._calibrate import (
        CalibrationRun,
        calibrate_measurements,
    )
    from kinecal.workflows._compare import (
        ModelComparison,
        compare_measurements,
    )
    from kinecal.workflows._compensate import (
        ProgramCompensation,
        TargetCompensation,
        compensate_program,
        compensate_targets,
    )
    from kinecal.workflows._evaluate import (
        ModelEvaluation,
        evaluate_measurements,
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
    from kinecal.workflows._iso9283 import (
        IsoTestProgram,
        IsoTestResult,
        evaluate_iso_test,
        iso_test_program,
    )
    from kinecal.workflows._plan import (
        PlanRun,
        PlanSetup,
        PoseCandidates,
        plan_candidates,
        plan_measurements,
        plan_setup,
    )
    from kinecal.workflows._poses import (
        read_pose_file,
    )
    from kinecal.workflows._sensor import (
        CameraRun,
        SensorRun,
        calibrate_camera_images,
        calibrate_sensor_images,
        fit_cloud_sphere,
        reconstruct_scan,
    )
    from kinecal.workflows._sensor_sim import (
        RenderedSession,
        render_calibration_session,
        render_scan,
    )
    from kinecal.workflows._simulate import (
        SimulatedData,
        simulate_paper_experiment,
        simulate_robot_twin,
    )

__all__ = [
    "CalibrationRun",
    "CameraRun",
    "DemoRun",
    "ImportedRobot",
    "IsoTestProgram",
    "IsoTestResult",
    "ModelComparison",
    "ModelEvaluation",
    "ModelExport",
    "PlanRun",
    "PlanSetup",
    "PoseCandidates",
    "PoseReport",
    "ProgramCompensation",
    "RenderedSession",
    "SensorRun",
    "SimulatedData",
    "TargetCompensation",
    "calibrate_camera_images",
    "calibrate_measurements",
    "calibrate_sensor_images",
    "compare_measurements",
    "compensate_program",
    "compensate_targets",
    "evaluate_iso_test",
    "evaluate_measurements",
    "export_model",
    "fit_cloud_sphere",
    "forward_pose",
    "import_urdf_robot",
    "iso_test_program",
    "paper_demo",
    "plan_candidates",
    "plan_measurements",
    "plan_setup",
    "read_pose_file",
    "reconstruct_scan",
    "render_calibration_session",
    "render_scan",
    "simulate_paper_experiment",
    "simulate_robot_twin",
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
        "_sensor": (
            "CameraRun",
            "SensorRun",
            "calibrate_camera_images",
            "calibrate_sensor_images",
            "fit_cloud_sphere",
            "reconstruct_scan",
        ),
        "_sensor_sim": (
            "RenderedSession",
            "render_calibration_session",
            "render_scan",
        ),
        "_compare": (
            "ModelComparison",
            "compare_measurements",
        ),
        "kinecal.demo": (
            "DemoRun",
            "paper_demo",
        ),
        "_compensate": (
            "ProgramCompensation",
            "TargetCompensation",
            "compensate_program",
            "compensate_targets",
        ),
        "_simulate": (
            "SimulatedData",
            "simulate_paper_experiment",
            "simulate_robot_twin",
        ),
        "_plan": (
            "PlanRun",
            "PlanSetup",
            "PoseCandidates",
            "plan_candidates",
            "plan_measurements",
            "plan_setup",
        ),
        "_evaluate": (
            "ModelEvaluation",
            "evaluate_measurements",
        ),
        "_poses": ("read_pose_file",),
        "_iso9283": (
            "IsoTestProgram",
            "IsoTestResult",
            "evaluate_iso_test",
            "iso_test_program",
        ),
    },
)
