"""The model's exact parameter Jacobian in numpy (Eq. 28), from a forward state.

.. math::
    J = \\frac{\\partial (p_{user}, R_{user,cam})}{\\partial \\eta}
    = \\Big[ J_{frames} \\;\\; J_{rows} \\;\\; J(\\theta) \\frac{\\partial \\theta}
    {\\partial \\eta_C} \\;\\; J(\\theta) \\frac{\\partial \\theta}{\\partial
    (\\lambda^*, s^*)} \\Big] + J(\\theta)\\, \\lambda^* \\odot
    \\frac{\\partial \\tau}{\\partial \\eta}

Every column is in the user frame, position rows then rotation rows ``dR = [w] R``. The
last term is the compliance torques' dependence on the arm's geometry, which makes the
Jacobian exact (checked against finite differences): each geometric parameter moves the
downstream frames by a twist, and :func:`~kinecal.models._compliance.torque_adjoint`
turns the twists into weighted torque derivatives. The compiled kernel
(:mod:`kinecal.models._kernel`) computes the same columns.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from kinecal.models._chain import ChainFrames, rotate, vcross
from kinecal.models._compliance import torque_adjoint
from kinecal.models._definition import ALPHA, BETA, OFF, A, D, ModelDefinition
from kinecal.models._inputs import ModelInputs
from kinecal.models._numpy_forward import ForwardState, joint_columns
from kinecal.typing import Float

__all__ = ["jacobian"]


def jacobian(
    defn: ModelDefinition,
    fw: ForwardState,
    *,
    orientation: bool,
    products: bool,
    alloc: Callable[[tuple[int, ...]], Float],
) -> Float:
    """Jacobian columns (P + K, c, N) at the forward state ``fw``, parameter-major.

    Parameters
    ----------
    defn : ModelDefinition
        The definition ``fw`` was computed with.
    fw : ForwardState
        With ``R_uc`` when ``orientation``.
    orientation : bool
        Rotation rows too (c = 6; else c = 3).
    products : bool
        Append the K columns of :attr:`ModelDefinition.link_products`.
    alloc : callable
        Storage of the result, from its shape (every entry is written).
    """
    N, n = fw.inputs.q_ctrl.shape
    fr = fw.fr
    # Columns (user frame), position rows 0:3 and rotation rows 3:6, stored
    # parameter-major: every column of every component is a contiguous row.
    P = defn.size
    c = 6 if orientation else 3
    K = len(defn.products) if products else 0
    # Every row is assigned below; only the parts no term writes are zeroed.
    Jb = alloc((P + K, c, N))
    Z = fr.cols[:n, 2]  # (n, 3, N): joint i + 1 turns about z_i
    rot_cols = vcross(Z, fw.p_u - fr.origin[:n])  # rotation about z_i
    G = joint_columns(defn, Z, rot_cols, orientation)  # d output / d theta_i
    _joint_rows(defn, fw, Jb, Z, rot_cols, orientation)
    _cam_rows(defn, fw, Jb, orientation)
    _angle_terms(defn, fw, Jb, G, products)
    _base_rows(defn, fw, Jb, orientation)
    return Jb


def _joint_rows(
    defn: ModelDefinition,
    fw: ForwardState,
    Jb: Float,
    Z: Float,
    rot_cols: Float,
    orientation: bool,
) -> None:
    """Joint rows (Eq. 10): a turn about z_i, a slide along z_i or x_i, a turn about x_i
    (or y_i for a Hayati beta), each moving the point and every frame after the row."""
    fr, p_u = fw.fr, fw.p_u
    ax = fr.a_dir
    alpha_cols = vcross(ax, p_u - fr.origin[1:])
    for i in range(fw.inputs.q_ctrl.shape[1]):
        idx = defn.row_idx[i]
        if idx[OFF] >= 0:
            Jb[idx[OFF], :3] = rot_cols[i]
            if orientation:
                Jb[idx[OFF], 3:] = Z[i]
        if idx[D] >= 0:
            Jb[idx[D], :3] = Z[i]
            Jb[idx[D], 3:] = 0.0
        if idx[A] >= 0:
            Jb[idx[A], :3] = ax[i]
            Jb[idx[A], 3:] = 0.0
        if idx[ALPHA] >= 0:
            Jb[idx[ALPHA], :3] = alpha_cols[i]
            if orientation:
                Jb[idx[ALPHA], 3:] = ax[i]
        if idx[BETA] >= 0:
            y_i = fr.cols[i + 1, 1]
            Jb[idx[BETA], :3] = vcross(y_i, p_u - fr.origin[i + 1])
            if orientation:
                Jb[idx[BETA], 3:] = y_i


def _cam_rows(
    defn: ModelDefinition, fw: ForwardState, Jb: Float, orientation: bool
) -> None:
    """Cam frame parameters (Eq. 9), per marker."""
    spec, n = defn.spec, fw.inputs.q_ctrl.shape[1]
    R_fl = fw.fr.cols[n]
    single_m, mi = len(spec.markers) == 1, fw.inputs.marker_index
    rel_cam = rotate(R_fl, fw.p_cam_fl)
    cam_axes = defn.cam_axes(fw.params) if spec.cam_rotation else None
    for m in range(len(spec.markers)):
        mask = 1.0 if single_m else (mi == m).astype(np.float64)
        cols = defn.cam_idx[m]
        for k in range(3):
            Jb[cols[k], :3] = R_fl[k] * mask
            Jb[cols[k], 3:] = 0.0
        if cam_axes is not None:
            ax_b = np.einsum("cin,ck->kin", R_fl, cam_axes[m])  # (3, 3, N), r w p
            Jb[cols[3:], :3] = vcross(ax_b, rel_cam) * mask
            if orientation:
                Jb[cols[3:], 3:] = ax_b * mask


def _angle_terms(
    defn: ModelDefinition, fw: ForwardState, Jb: Float, G: Float, products: bool
) -> None:
    """Parameters acting through the joint angles (Eq. 14, 21-26): J(theta) times the
    derivative of the angle, plus the torques' dependence on the geometry."""
    spec, p, P = defn.spec, fw.params, defn.size
    turns: dict[int, Float] = {}
    if spec.load:
        fr0, p_load, tau, link_T = fw.fr0, fw.p_load, fw.tau, fw.link_T
        assert fr0 is not None and p_load is not None and tau is not None
        H = G * p[defn.lam_idx, None, None]  # lambda* d output / d theta
        turns = _add_torque_geometry(defn, p, fw.inputs, fr0, p_load, fw.g, H, Jb)
        Jb[defn.lam_idx] = G * tau[:, None, :]  # Eq. (24)
        if link_T is not None:
            # d output / d s_k = sum_j H_j link_T[j, k] over the pattern's joints (Eq. 26)
            Jb[defn.link_slice] = 0.0
            for j, k in defn.products:
                Jb[defn.link_start + k] += H[j] * link_T[j, k]
            if products:
                for i, (j, k) in enumerate(defn.products):
                    Jb[P + i] = G[j] * link_T[j, k]
    # An NTM term turns its joint: through the chain (G) and through the torques.
    nb = len(defn.ntm_terms)
    for k, j in enumerate(spec.ntm_joints):
        sl = slice(defn.ntm_start + k * nb, defn.ntm_start + (k + 1) * nb)
        d_turn = G[j - 1] + turns[j] if j in turns else G[j - 1]
        Jb[sl] = d_turn * fw.ntm_bases[k][:, None, :]  # Eq. (14), (17)


def _base_rows(
    defn: ModelDefinition, fw: ForwardState, Jb: Float, orientation: bool
) -> None:
    """User frame parameters (Eq. 8), per set."""
    spec, N = defn.spec, fw.inputs.q_ctrl.shape[0]
    single_s, si = len(spec.sets) == 1, fw.inputs.set_index
    base_axes = defn.base_axes(fw.params)
    for k_set in range(len(spec.sets)):
        mask = np.ones(N) if single_s else (si == k_set).astype(np.float64)
        cols = defn.base_idx[k_set]
        Jb[cols[:3]] = 0.0
        for k in range(3):
            Jb[cols[k], k] = mask
        axes = base_axes[k_set]
        rel = (fw.p_u - fw.t_base[k_set][:, None]) * mask
        Jb[cols[3:], :3] = vcross(axes.T[:, :, None], rel)
        if orientation:
            Jb[cols[3:], 3:] = axes.T[:, :, None] * mask


def _add_torque_geometry(
    defn: ModelDefinition,
    p: Float,
    inputs: ModelInputs,
    fr0: ChainFrames,
    p_load: Float,
    g: Float,
    H: Float,
    Jb: Float,
) -> dict[int, Float]:
    """Add ``sum_j H_j d tau_j / d psi`` for every geometric parameter psi.

    The compliance torques depend on the arm's geometry (joint rows, joint angles
    through the NTM terms, the load point); each such parameter moves the downstream
    frames by a twist, and :func:`torque_adjoint` turns the twists into weighted
    torque derivatives.

    Returns the term of a unit turn of each NTM joint (joint -> (c, N)): the caller
    scales it by the joint's Fourier basis with the chain's own column.
    """
    n = defn.n_joints
    spec = defn.spec
    link = None
    if spec.link in ("paper", "rfcm"):
        sw = defn.self_weight
        assert sw is not None
        link = (
            spec.link,
            (sw.shoulder, sw.elbow, sw.wrist_frame),
            defn.x_sign,
            p[defn.link_start : defn.link_start + defn.n_lumped],
        )
    bodies = None
    if spec.link_bodies:
        end = defn.link_start + len(defn.link_names)
        start = end - 4 * len(spec.link_bodies)
        bodies = (spec.link_bodies, p[start:end])
    adjoint = torque_adjoint(
        fr0, p_load, g, defn.prismatic, H, inputs.load_scale, link, bodies
    )
    ntm = set(spec.ntm_joints)
    turns: dict[int, Float] = {}
    for f, M, V in adjoint.sweep():
        if f == n + 1:  # the load point moves with the first marker's translation
            Jb[defn.cam_idx[0][:3]] += _apply(V, fr0.cols[n])
            continue
        # Row i = f - 1 moves the frames f.. by the twist of each of its parameters.
        i = f - 1
        idx = defn.row_idx[i]
        z, o = fr0.cols[i, 2], fr0.origin[i]
        ax, o1 = fr0.a_dir[i], fr0.origin[i + 1]
        if idx[OFF] >= 0 or f in ntm:  # joint f turning about z_i through o_i
            d_turn = _apply(M, z) + _apply(V, vcross(o, z))
            if idx[OFF] >= 0:
                Jb[idx[OFF]] += d_turn
            if f in ntm:
                turns[f] = d_turn
        if idx[D] >= 0:
            Jb[idx[D]] += _apply(V, z)
        if idx[A] >= 0:
            Jb[idx[A]] += _apply(V, ax)
        if idx[ALPHA] >= 0:
            Jb[idx[ALPHA]] += _apply(M, ax) + _apply(V, vcross(o1, ax))
        if idx[BETA] >= 0:
            y = fr0.cols[i + 1, 1]
            Jb[idx[BETA]] += _apply(M, y) + _apply(V, vcross(o1, y))
    return turns


def _apply(M: Float, w: Float) -> Float:
    """``M w`` per pose for M (c, 3, N): w (3, N) gives (c, N), w (k, 3, N) gives (k, c, N)."""
    if w.ndim == 2:
        return np.einsum("cbn,bn->cn", M, w)
    return np.einsum("cbn,kbn->kcn", M, w)
