"""Rigid transforms: construction, inverse, point mapping, SE(3) exponential and logarithm.

``T_a_b`` is the pose of frame b in frame a; ``p_a = T_a_b @ p_b``. The tangent vector is
translation first, ``xi = [v, omega]``, and perturbations are right (local):
``T ⊕ xi = T @ exp(xi)``. See ``docs/conventions.md``.
"""

from __future__ import annotations

import numpy as np

from kinecal.geometry._so3 import so3_exp, so3_left_jacobian, so3_log
from kinecal.typing import ArrayLike, Float, Pose

__all__ = [
    "make_transform",
    "se3_exp",
    "se3_log",
    "transform_inv",
    "transform_points",
    "transform_vectors",
]


def make_transform(R: ArrayLike, t: ArrayLike) -> Pose:
    """Homogeneous transform from a rotation ``(..., 3, 3)`` and translation ``(..., 3)``."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have shape (..., 3, 3); got {R.shape}.")
    if t.shape[-1:] != (3,):
        raise ValueError(f"t must have shape (..., 3); got {t.shape}.")
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros((*shape, 4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def _check_pose(T: Float, name: str = "T") -> None:
    if T.shape[-2:] != (4, 4):
        raise ValueError(f"{name} must have shape (..., 4, 4); got {T.shape}.")


def transform_inv(T: ArrayLike) -> Pose:
    """Inverse of rigid transforms ``(..., 4, 4)``: ``T_b_a`` from ``T_a_b``."""
    T = np.asarray(T, dtype=np.float64)
    _check_pose(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def transform_points(T: ArrayLike, p: ArrayLike) -> Float:
    """Map points ``p_b`` (..., 3) through ``T_a_b`` (..., 4, 4) to ``p_a``."""
    T = np.asarray(T, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    _check_pose(T)
    if p.shape[-1:] != (3,):
        raise ValueError(f"p must have shape (..., 3); got {p.shape}.")
    return np.einsum("...ij,...j->...i", T[..., :3, :3], p) + T[..., :3, 3]


def transform_vectors(T: ArrayLike, v: ArrayLike) -> Float:
    """Rotate free vectors ``v_b`` (..., 3) into frame a (no translation)."""
    T = np.asarray(T, dtype=np.float64)
    _check_pose(T)
    return np.einsum(
        "...ij,...j->...i", T[..., :3, :3], np.asarray(v, dtype=np.float64)
    )


def se3_exp(xi: ArrayLike) -> Pose:
    """Exponential map of twists ``xi = [v, omega]`` (..., 6) to transforms (..., 4, 4)."""
    xi = np.asarray(xi, dtype=np.float64)
    if xi.shape[-1:] != (6,):
        raise ValueError(f"xi must have shape (..., 6); got {xi.shape}.")
    v, w = xi[..., :3], xi[..., 3:]
    R = so3_exp(w)
    t = np.einsum("...ij,...j->...i", so3_left_jacobian(w), v)
    return make_transform(R, t)


def se3_log(T: ArrayLike) -> Float:
    """Logarithm of rigid transforms (..., 4, 4): twists ``[v, omega]`` (..., 6)."""
    T = np.asarray(T, dtype=np.float64)
    _check_pose(T)
    w = so3_log(T[..., :3, :3])
    J = so3_left_jacobian(w)
    v = np.linalg.solve(J, T[..., :3, 3][..., None])[..., 0]
    return np.concatenate([v, w], axis=-1)
