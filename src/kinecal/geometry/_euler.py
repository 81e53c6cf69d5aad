"""Euler-angle frames of the paper (Eq. 8-9), FANUC WPR and URDF roll-pitch-yaw.

The paper writes a frame as ``Trans(x, y, z) · Rz(r) · Ry(w) · Rx(p)`` (Eq. 8, 9). FANUC's
WPR (W about x, P about y, R about z) is the same rotation, ``R = Rz(R) · Ry(P) · Rx(W)``,
listed x-angle first; URDF/pinocchio ``rpy`` (roll, pitch, yaw) is identical to WPR.

.. math:: T(x, y, z, r, w, p) = \\mathrm{Trans}(x, y, z)\\, R_z(r)\\, R_y(w)\\, R_x(p)
"""

from __future__ import annotations

import numpy as np

from kinecal.geometry._se3 import make_transform
from kinecal.typing import ArrayLike, Float, Pose, Rotation

__all__ = [
    "euler_transform",
    "euler_zyx_to_matrix",
    "matrix_to_euler_zyx",
    "matrix_to_rpy",
    "matrix_to_wpr",
    "rpy_to_matrix",
    "transform_to_euler",
    "wpr_to_matrix",
]

_GIMBAL = 1e-9


def euler_zyx_to_matrix(rwp: ArrayLike) -> Rotation:
    """``Rz(r) · Ry(w) · Rx(p)`` from angles ``[r, w, p]`` (..., 3) [rad]; Eq. (8)-(9)."""
    a = np.asarray(rwp, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"rwp must have shape (..., 3); got {a.shape}.")
    cr, sr = np.cos(a[..., 0]), np.sin(a[..., 0])
    cw, sw = np.cos(a[..., 1]), np.sin(a[..., 1])
    cp, sp = np.cos(a[..., 2]), np.sin(a[..., 2])
    R = np.empty((*a.shape[:-1], 3, 3))
    # Eq. (8): Rot_z(r) Rot_y(w) Rot_x(p), multiplied out.
    R[..., 0, 0] = cr * cw
    R[..., 0, 1] = cr * sw * sp - sr * cp
    R[..., 0, 2] = cr * sw * cp + sr * sp
    R[..., 1, 0] = sr * cw
    R[..., 1, 1] = sr * sw * sp + cr * cp
    R[..., 1, 2] = sr * sw * cp - cr * sp
    R[..., 2, 0] = -sw
    R[..., 2, 1] = cw * sp
    R[..., 2, 2] = cw * cp
    return R


def matrix_to_euler_zyx(R: ArrayLike) -> Float:
    """Angles ``[r, w, p]`` (..., 3) [rad] with ``R = Rz(r) Ry(w) Rx(p)``, w in [-pi/2, pi/2].

    At gimbal lock (``|w| = pi/2``) ``p`` is set to 0 and ``r`` carries the rotation.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have shape (..., 3, 3); got {R.shape}.")
    cw = np.hypot(R[..., 0, 0], R[..., 1, 0])
    w = np.arctan2(-R[..., 2, 0], cw)
    lock = cw < _GIMBAL
    r = np.where(
        lock,
        np.arctan2(-R[..., 0, 1], R[..., 1, 1]),
        np.arctan2(R[..., 1, 0], R[..., 0, 0]),
    )
    p = np.where(lock, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    return np.stack([r, w, p], axis=-1)


def euler_transform(xyzrwp: ArrayLike) -> Pose:
    """``Trans(x, y, z) Rz(r) Ry(w) Rx(p)`` from ``[x, y, z, r, w, p]`` (..., 6) [m, rad].

    Implements Eq. (8) and Eq. (9) of the paper.
    """
    v = np.asarray(xyzrwp, dtype=np.float64)
    if v.shape[-1:] != (6,):
        raise ValueError(f"xyzrwp must have shape (..., 6); got {v.shape}.")
    return make_transform(euler_zyx_to_matrix(v[..., 3:]), v[..., :3])


def transform_to_euler(T: ArrayLike) -> Float:
    """Inverse of :func:`euler_transform`: ``[x, y, z, r, w, p]`` (..., 6) [m, rad]."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"T must have shape (..., 4, 4); got {T.shape}.")
    return np.concatenate([T[..., :3, 3], matrix_to_euler_zyx(T[..., :3, :3])], axis=-1)


def wpr_to_matrix(wpr: ArrayLike) -> Rotation:
    """FANUC ``[W, P, R]`` (..., 3) [rad] to ``Rz(R) Ry(P) Rx(W)``."""
    a = np.asarray(wpr, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"wpr must have shape (..., 3); got {a.shape}.")
    return euler_zyx_to_matrix(a[..., ::-1])


def matrix_to_wpr(R: ArrayLike) -> Float:
    """Rotation (..., 3, 3) to FANUC ``[W, P, R]`` (..., 3) [rad]."""
    return matrix_to_euler_zyx(R)[..., ::-1].copy()


def rpy_to_matrix(rpy: ArrayLike) -> Rotation:
    """URDF/pinocchio ``[roll, pitch, yaw]`` (..., 3) [rad]: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    return wpr_to_matrix(rpy)


def matrix_to_rpy(R: ArrayLike) -> Float:
    """Rotation (..., 3, 3) to URDF ``[roll, pitch, yaw]`` (..., 3) [rad]."""
    return matrix_to_wpr(R)
