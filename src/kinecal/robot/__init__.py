"""Robot descriptions: DH/MDH joint tables, coupling, limits, frames, built-in robots.

Each name loads its module on first use (:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal.robot._builtin import builtin_robot_names, load_robot
    from kinecal.robot._description import (
        DHChain,
        JointSpec,
        LinkMass,
        RobotDescription,
        SelfWeightSpec,
        dh_transforms,
    )
    from kinecal.robot._gravity import (
        MAX_COMPLIANCE,
        PRIOR_DEFLECTION,
        compliance_priors,
        gravity_torques,
        random_joint_poses,
    )
    from kinecal.robot._robot_file import load_robot_file
    from kinecal.robot._schema import dump_robot, robot_from_dict
    from kinecal.robot._urdf import robot_from_urdf

__all__ = [
    "MAX_COMPLIANCE",
    "PRIOR_DEFLECTION",
    "DHChain",
    "JointSpec",
    "LinkMass",
    "RobotDescription",
    "SelfWeightSpec",
    "builtin_robot_names",
    "compliance_priors",
    "dh_transforms",
    "dump_robot",
    "gravity_torques",
    "load_robot",
    "load_robot_file",
    "random_joint_poses",
    "robot_from_dict",
    "robot_from_urdf",
]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_builtin": (
            "builtin_robot_names",
            "load_robot",
        ),
        "_description": (
            "DHChain",
            "JointSpec",
            "LinkMass",
            "RobotDescription",
            "SelfWeightSpec",
            "dh_transforms",
        ),
        "_gravity": (
            "MAX_COMPLIANCE",
            "PRIOR_DEFLECTION",
            "compliance_priors",
            "gravity_torques",
            "random_joint_poses",
        ),
        "_robot_file": ("load_robot_file",),
        "_schema": (
            "dump_robot",
            "robot_from_dict",
        ),
        "_urdf": ("robot_from_urdf",),
    },
)
