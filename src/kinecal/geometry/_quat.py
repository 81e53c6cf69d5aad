"""Unit quaternions, scalar first: ``quat_wxyz = [w, x, y, z]``.

``q`` and ``-q`` are the same rotation; :func:`matrix_to_quat_wxyz` returns ``w >= 0``.
"""

from __future__ import annotations

import numpy as np

from kinecal.typing import ArrayLike, Float, Rotation

__all__ = ["matrix_to_quat_wxyz", "quat_wxyz_to_matrix"]


def quat_wxyz_to_matrix(quat_wxyz: ArrayLike, *, normalize: bool = True) -> Rotation:
    """Rotation matrices (..., 3, 3) from quaternions ``[w, x, y, z]`` (..., 4).

    Parameters
    ----------
    quat_wxyz : array_like, shape (..., 4)
    normalize : bool
        Divide by the norm first (default). A zero quaternion raises ``ValueError``.
    """
    q = np.asarray(quat_wxyz, dtype=np.float64)
    if q.shape[-1:] != (4,):
        raise ValueError(f"quat_wxyz must have shape (..., 4); got {q.shape}.")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(n < 1e-12):
        raise ValueError("quat_wxyz contains a zero quaternion; it has no rotation.")
    if normalize:
        q = q / n
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat_wxyz(R: ArrayLike) -> Float:
    """Quaternions ``[w, x, y, z]`` (..., 4) with ``w >= 0`` from rotations (..., 3, 3).

    Uses the largest of the four candidate denominators (Shepperd's method), so it is
    accurate for every rotation, including half turns.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape[-2:] != (3, 3):
        raise ValueError(f"R must have shape (..., 3, 3); got {R.shape}.")
    m00, m11, m22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    cand = np.stack(
        [
            1 + m00 + m11 + m22,
            1 + m00 - m11 - m22,
            1 - m00 + m11 - m22,
            1 - m00 - m11 + m22,
        ],
        axis=-1,
    )
    k = np.argmax(cand, axis=-1)
    s = 2.0 * np.sqrt(
        np.maximum(np.take_along_axis(cand, k[..., None], -1)[..., 0], 1e-300)
    )
    d21 = R[..., 2, 1] - R[..., 1, 2]
    d02 = R[..., 0, 2] - R[..., 2, 0]
    d10 = R[..., 1, 0] - R[..., 0, 1]
    s01 = R[..., 0, 1] + R[..., 1, 0]
    s02 = R[..., 0, 2] + R[..., 2, 0]
    s12 = R[..., 1, 2] + R[..., 2, 1]
    opts = [
        (0.25 * s, d21 / s, d02 / s, d10 / s),
        (d21 / s, 0.25 * s, s01 / s, s02 / s),
        (d02 / s, s01 / s, 0.25 * s, s12 / s),
        (d10 / s, s02 / s, s12 / s, 0.25 * s),
    ]
    Q = np.stack([np.stack(o, axis=-1) for o in opts], axis=-2)  # (..., 4 cases, 4)
    q = np.take_along_axis(Q, k[..., None, None], axis=-2)[..., 0, :]
    q *= np.where(q[..., :1] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)
