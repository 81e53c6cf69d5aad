"""Closed-form rigid fits: Kabsch/Umeyama point-set registration and AX = YB.

References
----------
.. [Umeyama1991] S. Umeyama, "Least-squares estimation of transformation parameters
   between two point patterns", IEEE TPAMI 13(4), 1991.
.. [Shah2013] M. Shah, "Solving the robot-world/hand-eye calibration problem using the
   Kronecker product", ASME J. Mechanisms Robotics 5(3), 2013.
"""

from __future__ import annotations

import numpy as np

from kinecal.geometry._se3 import make_transform
from kinecal.geometry._so3 import project_to_so3, so3_exp
from kinecal.typing import ArrayLike, Float, Pose

__all__ = ["kabsch_umeyama", "rigid_fit_nearest", "solve_axyb"]


def kabsch_umeyama(
    p_src: ArrayLike,
    p_dst: ArrayLike,
    weights: ArrayLike | None = None,
    *,
    with_scale: bool = False,
) -> tuple[Pose, float]:
    """Rigid (or similarity) transform ``T_dst_src`` minimising ``sum w |p_dst - T p_src|^2``.

    Parameters
    ----------
    p_src, p_dst : array_like, shape (n, 3)
        Corresponding points, expressed in the source and destination frames.
    weights : array_like, shape (n,), optional
        Non-negative weights (default: all ones).
    with_scale : bool
        Also estimate a uniform scale (Umeyama); otherwise the scale is 1 (Kabsch).

    Returns
    -------
    T_dst_src : ndarray, shape (4, 4)
        Rotation and translation; the scale, if any, is returned separately.
    scale : float

    Raises
    ------
    ValueError
        Shapes differ, fewer than 3 points, or the points are collinear.
    """
    a = np.asarray(p_src, dtype=np.float64)
    b = np.asarray(p_dst, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape:
        raise ValueError(
            f"p_src and p_dst must both have shape (n, 3); got {a.shape} and {b.shape}."
        )
    n = a.shape[0]
    if n < 3:
        raise ValueError(f"kabsch_umeyama needs at least 3 point pairs; got {n}.")
    w = np.ones(n) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (n,) or np.any(w < 0) or w.sum() <= 0:
        raise ValueError("weights must be non-negative, shape (n,), and not all zero.")
    w = w / w.sum()
    ca = w @ a
    cb = w @ b
    A = a - ca
    B = b - cb
    H = (A * w[:, None]).T @ B  # cross-covariance, src -> dst
    U, S, Vt = np.linalg.svd(H)
    if S[1] <= 1e-12 * max(S[0], 1e-300):
        raise ValueError(
            "kabsch_umeyama: the points are collinear; rotation is undefined."
        )
    d = np.sign(np.linalg.det(Vt.T @ U.T))
    D = np.diag([1.0, 1.0, d if d != 0 else 1.0])
    R = Vt.T @ D @ U.T
    scale = 1.0
    if with_scale:
        var_a = float(np.sum(w * np.sum(A * A, axis=1)))
        scale = float(np.sum(S * np.diag(D)) / var_a)
    t = cb - scale * R @ ca
    return make_transform(R, t), scale


def rigid_fit_nearest(
    p_src: ArrayLike, p_dst: ArrayLike, R_start: ArrayLike
) -> tuple[Float, Float, bool]:
    """The rigid motion ``p_dst ≈ R p_src + t`` (Kabsch), also for degenerate point sets.

    Parameters
    ----------
    p_src, p_dst : (n, 3) corresponding points [m].
    R_start : (3, 3) rotation to stay close to where the points do not fix it.

    Returns
    -------
    R, t : the rotation and translation.
    determined : False where the points (one point, or all on one line) leave a rotation
        free; ``R`` is then the rotation nearest ``R_start`` that fits them.
    """
    a = np.asarray(p_src, dtype=np.float64)
    b = np.asarray(p_dst, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape or a.shape[0] == 0:
        raise ValueError(
            f"p_src and p_dst must both have shape (n, 3), n >= 1; got {a.shape} and "
            f"{b.shape}."
        )
    if a.shape[0] >= 3:
        try:
            T, _ = kabsch_umeyama(a, b)
            return T[:3, :3], T[:3, 3], True
        except ValueError:  # collinear: fall through
            pass
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    A, B = a - ca, b - cb
    R = np.array(R_start, dtype=np.float64)
    if np.abs(A).max(initial=0.0) > 0.0 and np.abs(B).max(initial=0.0) > 0.0:
        u_src = np.linalg.svd(A, full_matrices=False)[2][0]
        u_dst = np.linalg.svd(B, full_matrices=False)[2][0]
        if float(np.sum((A @ u_src) * (B @ u_dst))) < 0.0:
            u_dst = -u_dst
        v = R @ u_src  # the line's direction as R_start maps it; turn it onto u_dst
        axis = np.cross(v, u_dst)
        angle = np.arctan2(np.linalg.norm(axis), float(v @ u_dst))
        if np.linalg.norm(axis) > 1e-15:
            R = so3_exp(axis / np.linalg.norm(axis) * angle) @ R
        elif angle > np.pi / 2:  # opposite directions: half a turn about a normal
            normal = np.linalg.svd(v[None, :])[2][-1]
            R = so3_exp(normal * np.pi) @ R
    return R, cb - R @ ca, False


def solve_axyb(A: ArrayLike, B: ArrayLike) -> tuple[Pose, Pose]:
    """Closed-form solution of ``A_i X = Y B_i`` for rigid X and Y (Shah's method).

    Parameters
    ----------
    A, B : array_like, shape (n, 4, 4)
        Paired rigid transforms, ``n >= 3`` with rotations that are not all coaxial.

    Returns
    -------
    X, Y : ndarray, shape (4, 4)
    """
    A = np.asarray(A, dtype=np.float64)
    B = np.asarray(B, dtype=np.float64)
    if A.ndim != 3 or A.shape[1:] != (4, 4) or A.shape != B.shape:
        raise ValueError(
            f"A and B must both have shape (n, 4, 4); got {A.shape}, {B.shape}."
        )
    n = A.shape[0]
    if n < 3:
        raise ValueError(f"solve_axyb needs at least 3 pose pairs; got {n}.")
    RA, RB = A[:, :3, :3], B[:, :3, :3]
    # R_A R_X R_B^T = R_Y  ->  (R_B kron R_A) vec(R_X) - vec(R_Y) = 0 (column-major vec)
    K = np.einsum("nij,nkl->nikjl", RB, RA).reshape(n, 9, 9)
    M = np.concatenate([K, -np.broadcast_to(np.eye(9), (n, 9, 9))], axis=2).reshape(
        9 * n, 18
    )
    _, s, Vt = np.linalg.svd(M, full_matrices=False)
    if s[-2] <= 1e-9 * s[0]:
        raise ValueError(
            "solve_axyb: the rotations do not determine X and Y (too little motion)."
        )
    v = Vt[-1]
    Xr = v[:9].reshape(3, 3, order="F")
    Yr = v[9:].reshape(3, 3, order="F")
    det = np.linalg.det(Xr)
    alpha = np.sign(det) / abs(det) ** (1.0 / 3.0)
    RX = project_to_so3(alpha * Xr)
    RY = project_to_so3(alpha * Yr)
    # R_A t_X + t_A = R_Y t_B + t_Y  ->  [R_A, -I] [t_X; t_Y] = R_Y t_B - t_A
    lhs = np.concatenate([RA, -np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(
        3 * n, 6
    )
    rhs = (np.einsum("ij,nj->ni", RY, B[:, :3, 3]) - A[:, :3, 3]).reshape(3 * n)
    sol, *_ = np.linalg.lstsq(lhs, rhs, rcond=None)
    return make_transform(RX, sol[:3]), make_transform(RY, sol[3:])
