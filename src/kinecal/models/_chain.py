"""Vectorised serial-chain kinematics: every joint frame for a batch of poses.

A row is ``Rz(theta) · Tz(d) · Tx(a) · Rx(alpha) · Ry(beta)`` (standard DH when
``beta = 0``; Hayati's row when ``d = 0`` and ``beta`` is free). Frame 0 is the chain's
base; frame i is the frame after row i. Joint i turns about ``z_{i-1}`` through ``o_{i-1}``.

Points and axes are returned in the chain's base frame; the caller maps them on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.typing import Float

__all__ = ["ChainFrames", "chain_frames", "cross"]


def cross(a: Float, b: Float) -> Float:
    """Cross product over the last axis (faster than ``np.cross`` for small batches)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


@dataclass(frozen=True)
class ChainFrames:
    """Frames of a chain for N poses, in the chain's base frame.

    Attributes
    ----------
    R : ndarray, shape (N, n + 1, 3, 3)
        Rotation of frame k (``R[:, 0]`` is the identity).
    o : ndarray, shape (N, n + 1, 3)
        Origin of frame k [m].
    a_axis : ndarray, shape (N, n, 3)
        Direction of row i's ``a`` translation, which is also its ``alpha`` rotation axis
        (``x_i`` for a DH row; ``x_i`` before ``Ry(beta)`` for a Hayati row).
    """

    R: Float
    o: Float
    a_axis: Float

    @property
    def n(self) -> int:
        return int(self.R.shape[1] - 1)

    def z(self, k: int) -> Float:
        """Axis ``z_k`` (N, 3): the axis of joint k + 1."""
        return self.R[:, k, :, 2]


def chain_frames(
    theta: Float,
    d: Float,
    a: Float,
    alpha: Float,
    beta: Float | None = None,
) -> ChainFrames:
    """Frames of a chain of rows ``Rz(theta) Tz(d) Tx(a) Rx(alpha) Ry(beta)``.

    Parameters
    ----------
    theta : ndarray, shape (N, n)
        Total rotation of each row about its z [rad] (joint angle plus offset).
    d : ndarray, shape (N, n) or (n,)
        Translation along z [m] (plus the joint value for prismatic joints).
    a, alpha : ndarray, shape (n,)
        Translation along x [m] and twist about x [rad].
    beta : ndarray, shape (n,), optional
        Hayati twist about y [rad]; rows with ``beta == 0`` skip it.

    Returns
    -------
    ChainFrames
    """
    N, n = theta.shape
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    R = np.empty((N, n + 1, 3, 3))
    o = np.empty((N, n + 1, 3))
    R[:, 0] = np.eye(3)
    o[:, 0] = 0.0
    a_axis = np.empty((N, n, 3))
    d = np.broadcast_to(d, (N, n))
    # Row i multiplies the previous frame's columns (x, y, z) = (c0, c1, c2) by
    # Rz(theta) Rx(alpha): x' = c0 ct + c1 st, y' = v ca + c2 sa, z' = -v sa + c2 ca with
    # v = -c0 st + c1 ct; the origin moves by a x' + d c2. Every operation is on (N, 3)
    # columns, batched over poses (no 3x3 matrix products).
    for i in range(n):
        c0, c1, c2 = R[:, i, :, 0], R[:, i, :, 1], R[:, i, :, 2]
        cti, sti = ct[:, i, None], st[:, i, None]
        x = c0 * cti + c1 * sti
        v = c1 * cti - c0 * sti
        y = v * ca[i] + c2 * sa[i]
        z = c2 * ca[i] - v * sa[i]
        a_axis[:, i] = x
        o[:, i + 1] = o[:, i] + a[i] * x + d[:, i, None] * c2
        if beta is not None and beta[i] != 0.0:  # Ry(beta): x and z turn about y
            cb, sb = np.cos(beta[i]), np.sin(beta[i])
            x, z = x * cb - z * sb, x * sb + z * cb
        R[:, i + 1, :, 0] = x
        R[:, i + 1, :, 1] = y
        R[:, i + 1, :, 2] = z
    return ChainFrames(R=R, o=o, a_axis=a_axis)
