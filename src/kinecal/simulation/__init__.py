"""Digital twin: true robots, instruments, pose planning and the paper's experiments."""

from kinecal.simulation._experiments import (
    CERAMIC_SPHERES_MM,
    Experiment,
    experiment1,
    experiment2,
    planning_model,
)
from kinecal.simulation._instruments import (
    LaserTracker,
    PoseTracker,
    SphereSensor,
    add_outliers,
)
from kinecal.simulation._planning import (
    PlannedPoses,
    grid_poses,
    joint_ranges_deg,
    sphere_poses,
)
from kinecal.simulation._recovery import Recovery, noise_free, parameter_recovery
from kinecal.simulation._robot_sensor import (
    SENSOR_MOUNT_MM,
    robot_sensor_experiment,
    robot_sensor_truth,
    robot_sensor_twin,
    sensor_robot,
)
from kinecal.simulation._robot_twin import (
    gravity_torques,
    random_joint_poses,
    robot_experiment,
    robot_truth,
)
from kinecal.simulation._truth import (
    EXTRAS,
    PAPER_TABLES,
    TrueRobot,
    paper_truth,
    random_truth,
)

__all__ = [
    "CERAMIC_SPHERES_MM",
    "EXTRAS",
    "PAPER_TABLES",
    "SENSOR_MOUNT_MM",
    "Experiment",
    "LaserTracker",
    "PlannedPoses",
    "PoseTracker",
    "Recovery",
    "SphereSensor",
    "TrueRobot",
    "add_outliers",
    "experiment1",
    "experiment2",
    "gravity_torques",
    "grid_poses",
    "joint_ranges_deg",
    "noise_free",
    "paper_truth",
    "parameter_recovery",
    "planning_model",
    "random_joint_poses",
    "random_truth",
    "robot_experiment",
    "robot_sensor_experiment",
    "robot_sensor_truth",
    "robot_sensor_twin",
    "robot_truth",
    "sensor_robot",
    "sphere_poses",
]
