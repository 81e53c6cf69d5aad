"""Geometry: SO(3)/SE(3), Euler frames (Eq. 8-9), FANUC WPR, quaternions, rigid fits.

Conventions: ``docs/conventions.md``. Everything is batched over leading axes and in SI.
"""

from kinecal.geometry._euler import (
    euler_transform,
    euler_zyx_to_matrix,
    matrix_to_euler_zyx,
    matrix_to_rpy,
    matrix_to_wpr,
    rpy_to_matrix,
    transform_to_euler,
    wpr_to_matrix,
)
from kinecal.geometry._fit import kabsch_umeyama, rigid_fit_nearest, solve_axyb
from kinecal.geometry._quat import matrix_to_quat_wxyz, quat_wxyz_to_matrix
from kinecal.geometry._se3 import (
    make_transform,
    se3_exp,
    se3_log,
    transform_inv,
    transform_points,
    transform_vectors,
)
from kinecal.geometry._so3 import (
    project_to_so3,
    rot_x,
    rot_y,
    rot_z,
    skew,
    so3_exp,
    so3_left_jacobian,
    so3_log,
    so3_right_jacobian_inv,
)

__all__ = [
    "euler_transform",
    "euler_zyx_to_matrix",
    "kabsch_umeyama",
    "make_transform",
    "matrix_to_euler_zyx",
    "matrix_to_quat_wxyz",
    "matrix_to_rpy",
    "matrix_to_wpr",
    "project_to_so3",
    "quat_wxyz_to_matrix",
    "rigid_fit_nearest",
    "rot_x",
    "rot_y",
    "rot_z",
    "rpy_to_matrix",
    "se3_exp",
    "se3_log",
    "skew",
    "so3_exp",
    "so3_left_jacobian",
    "so3_log",
    "so3_right_jacobian_inv",
    "solve_axyb",
    "transform_inv",
    "transform_points",
    "transform_to_euler",
    "transform_vectors",
    "wpr_to_matrix",
]
