"""Compensation: corrected joint targets from a calibrated model (DESIGN §10), and the
calibrated kinematic part for the controller (a chain for URDF, a DH table)."""

from kinecal.compensation._compensate import (
    STATUS,
    CompensationResult,
    compensate,
    program_targets,
)
from kinecal.compensation._export import (
    COUPLING_MODES,
    Element,
    ExportedChain,
    GeometryLoss,
    check_chain,
    dh_description,
    export_chain,
    flange_offset,
    geometry_loss,
    has_compliance,
    kinematic_params,
    robot_base_offset,
)

__all__ = [
    "COUPLING_MODES",
    "STATUS",
    "CompensationResult",
    "Element",
    "ExportedChain",
    "GeometryLoss",
    "check_chain",
    "compensate",
    "dh_description",
    "export_chain",
    "flange_offset",
    "geometry_loss",
    "has_compliance",
    "kinematic_params",
    "program_targets",
    "robot_base_offset",
]
