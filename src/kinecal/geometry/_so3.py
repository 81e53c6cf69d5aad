"""Rotations: elementary rotations, skew matrices, the SO(3) exponential and logarithm.

All functions are batched over leading axes and never modify their inputs.
Conventions (active rotations, right-handed frames, ``R_a_b`` maps vectors expressed in
b into a) are fixed in ``docs/conventions.md``.

.. math:: \\exp([\\omega]) = I + \\frac{\\sin\\phi}{\\phi}[\\omega]
          + \\frac{1 - \\cos\\phi}{\\phi^2}[\\omega]^2, \\quad \\phi = \\|\\omega\\|
"""

from __future__ import annotations

import numpy as np

from kinecal.typing import ArrayLike, Float, Rotation

__all__ = [
    "project_to_so3",
    "rot_x",
    "rot_y",
    "rot_z",
    "skew",
    "so3_exp",
    "so3_left_jacobian",
    "so3_log",
    "so3_right_jacobian_inv",
]

_SMALL = 1e-6


def _as_float(x: ArrayLike) -> Float:
    return np.asarray(x, dtype=np.float64)


def _check_last(x: Float, n: int, name: str) -> None:
    if x.shape[-1:] != (n,):
        raise ValueError(f"{name} must have shape (..., {n}); got {x.shape}.")


def _check_mat(x: Float, name: str) -> None:
    if x.shape[-2:] != (3, 3):
        raise ValueError(f"{name} must have shape (..., 3, 3); got {x.shape}.")


def skew(v: ArrayLike) -> Float:
    """Skew-symmetric (cross-product) matrix ``[v]`` with ``[v] @ u == cross(v, u)``.

    Implements Eq. (20) of the paper.

    Parameters
    ----------
    v : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    v = _as_float(v)
    _check_last(v, 3, "v")
    out = np.zeros((*v.shape[:-1], 3, 3))
    # Eq. (20)
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def _elementary(angle: ArrayLike, axis: int) -> Rotation:
    a = _as_float(angle)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((*a.shape, 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., i, j] = -s
    out[..., j, i] = s
    return out


def rot_x(angle: ArrayLike) -> Rotation:
    """Rotation about x by ``angle`` [rad]; shape ``(*angle.shape, 3, 3)``."""
    return _elementary(angle, 0)


def rot_y(angle: ArrayLike) -> Rotation:
    """Rotation about y by ``angle`` [rad]; shape ``(*angle.shape, 3, 3)``."""
    return _elementary(angle, 1)


def rot_z(angle: ArrayLike) -> Rotation:
    """Rotation about z by ``angle`` [rad]; shape ``(*angle.shape, 3, 3)``."""
    return _elementary(angle, 2)


def so3_exp(omega: ArrayLike) -> Rotation:
    """Rotation matrix of the rotation vector ``omega`` (axis times angle) [rad].

    Parameters
    ----------
    omega : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    w = _as_float(omega)
    _check_last(w, 3, "omega")
    phi2 = np.sum(w * w, axis=-1)
    phi = np.sqrt(phi2)
    small = phi < _SMALL
    safe = np.where(small, 1.0, phi)
    # Taylor series below _SMALL keep full precision near identity.
    a = np.where(small, 1.0 - phi2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - phi2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    k = skew(w)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def so3_log(R: ArrayLike) -> Float:
    """Rotation vector (axis times angle, angle in [0, pi]) of rotation matrices.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3)
    """
    R = _as_float(R)
    _check_mat(R, "R")
    tr = R[..., 0, 0] + R[..., 1, 1] + R[..., 2, 2]
    vee = 0.5 * np.stack(
        [
            R[..., 2, 1] - R[..., 1, 2],
            R[..., 0, 2] - R[..., 2, 0],
            R[..., 1, 0] - R[..., 0, 1],
        ],
        axis=-1,
    )
    # vee = sin(phi) * axis; atan2 keeps phi accurate over the whole range [0, pi].
    sin_phi = np.linalg.norm(vee, axis=-1)
    phi = np.arctan2(sin_phi, 0.5 * (tr - 1.0))
    small = phi < 1e-4
    near_pi = phi > np.pi - 0.1
    scale = np.where(small, 1.0 + phi * phi / 6.0, phi / np.where(small, 1.0, sin_phi))
    out = scale[..., None] * vee
    if np.any(near_pi):
        # Near pi, sin(phi) ~ 0: recover the axis from the symmetric part R + R^T.
        Rn = R[near_pi]
        phin = phi[near_pi]
        B = 0.5 * (Rn + np.swapaxes(Rn, -1, -2)) - np.cos(phin)[
            ..., None, None
        ] * np.eye(3)
        B = B / (1.0 - np.cos(phin))[..., None, None]  # B = axis axis^T
        diag = np.diagonal(B, axis1=-2, axis2=-1)
        k = np.argmax(diag, axis=-1)
        idx = np.arange(len(k))
        axis = B[idx, k, :] / np.sqrt(np.maximum(diag[idx, k], 1e-300))[:, None]
        # Pick the sign consistent with the antisymmetric part.
        vn = vee[near_pi]
        sign = np.where(np.sum(axis * vn, axis=-1) < 0, -1.0, 1.0)
        out[near_pi] = axis * (sign * phin)[:, None]
    return out


def so3_left_jacobian(omega: ArrayLike) -> Float:
    """Left Jacobian of SO(3), ``exp(omega + d) ~ exp(J_l(omega) d) exp(omega)``.

    Parameters
    ----------
    omega : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    w = _as_float(omega)
    _check_last(w, 3, "omega")
    phi2 = np.sum(w * w, axis=-1)
    phi = np.sqrt(phi2)
    small = phi < 1e-4
    safe = np.where(small, 1.0, phi)
    a = np.where(small, 0.5 - phi2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    b = np.where(small, 1.0 / 6.0 - phi2 / 120.0, (safe - np.sin(safe)) / safe**3)
    k = skew(w)
    return np.eye(3) + a[..., None, None] * k + b[..., None, None] * (k @ k)


def so3_right_jacobian_inv(omega: ArrayLike) -> Float:
    """Inverse right Jacobian of SO(3).

    ``log(exp(omega) exp(d)) ~ omega + J_r^{-1}(omega) d`` for small ``d``.

    Parameters
    ----------
    omega : array_like, shape (..., 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    w = _as_float(omega)
    _check_last(w, 3, "omega")
    phi2 = np.sum(w * w, axis=-1)
    phi = np.sqrt(phi2)
    small = phi < 1e-4
    safe = np.where(small, 1.0, phi)
    c = np.where(
        small,
        1.0 / 12.0 + phi2 / 720.0,
        1.0 / (safe * safe) - (1.0 + np.cos(safe)) / (2.0 * safe * np.sin(safe)),
    )
    k = skew(w)
    return np.eye(3) + 0.5 * k + c[..., None, None] * (k @ k)


def project_to_so3(M: ArrayLike) -> Rotation:
    """Nearest rotation matrix (Frobenius norm) to ``M`` via SVD, det = +1.

    Parameters
    ----------
    M : array_like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    M = _as_float(M)
    _check_mat(M, "M")
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    d = np.where(d == 0, 1.0, d)
    D = np.ones((*M.shape[:-2], 3))
    D[..., 2] = d
    return (U * D[..., None, :]) @ Vt
