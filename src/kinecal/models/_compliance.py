"""Joint compliance terms (paper Sec. 3): transmission errors, payload and link weight.

All terms are joint-angle errors added to the kinematic angles before forward kinematics,
``theta = C q_ctrl + dtheta_C + dtheta_F + dtheta_Link`` (DESIGN §4):

.. math::
    \\delta\\theta_{C,j} = k_0 + \\sum_{h=1}^{N} k_{a h} \\cos(h q_j) + k_{b h} \\sin(h q_j)
    \\qquad \\text{(Eq. 16)}

    \\tau_F = J_v(\\theta)^T \\hat g, \\qquad
    \\tau_{Link, j} = z_j \\cdot (M_j \\times \\hat g), \\qquad
    \\delta\\theta_{F} + \\delta\\theta_{Link} = \\lambda^* \\odot (\\tau_F + \\tau_{Link})
    \\qquad \\text{(Eq. 21-26)}

Torques are per unit payload weight (``|F| = 1``): ``lambda* = |F| lambda`` [rad/m] and
``s* = s / |F|`` [m], as in Eq. 24 and Eq. 26. ``ĝ`` is the unit gravity direction in
the robot base frame. The torques are evaluated at the undeflected configuration; the
difference is second order in the deflection (~1e-8 rad). :func:`torque_derivatives`
gives their exact derivatives with respect to the geometry (for the Jacobian).
"""

from __future__ import annotations

import numpy as np

from kinecal.models._chain import ChainFrames, cross
from kinecal.typing import Float

__all__ = [
    "general_link_names",
    "general_link_torque_basis",
    "link_torque_basis",
    "load_torques",
    "ntm_basis",
    "ntm_names",
]


def ntm_names(order: int, offset: bool) -> list[str]:
    """Coefficient names of one joint's series: ``k0, ka1, kb1, ka2, kb2, ...``."""
    names = ["k0"] if offset else []
    for h in range(1, order + 1):
        names += [f"ka{h}", f"kb{h}"]
    return names


def ntm_basis(q: Float, order: int, offset: bool) -> Float:
    """Fourier basis of Eq. (16) at encoder angles ``q`` (N,) [rad], shape (N, nb).

    Columns follow :func:`ntm_names` (``w`` of Eq. 16 is 1).
    """
    cols = [np.ones_like(q)] if offset else []
    for h in range(1, order + 1):
        cols += [np.cos(h * q), np.sin(h * q)]  # Eq. (16)
    return np.stack(cols, axis=-1)


def load_torques(
    frames: ChainFrames, p_load: Float, g_hat: Float, prismatic: np.ndarray
) -> Float:
    """Joint torques of a unit weight along ``g_hat`` acting at ``p_load``, shape (N, n).

    ``tau = J_v^T g_hat`` (Eq. 21 with the wrench of Eq. 19-20 moved to the load point),
    where column j of ``J_v`` is ``z_{j-1} x (p - o_{j-1})`` (revolute) or ``z_{j-1}``
    (prismatic). Units: N·m per N = m.

    Parameters
    ----------
    frames : ChainFrames
    p_load : ndarray, shape (N, 3)
        Load point in the chain base frame [m].
    g_hat : ndarray, shape (3,)
        Unit gravity direction in the chain base frame.
    prismatic : ndarray of bool, shape (n,)
    """
    z = frames.R[:, :-1, :, 2]  # (N, n, 3) joint axes
    lever = p_load[:, None, :] - frames.o[:, :-1, :]
    # (z x r) . g == z . (r x g): one cross product with the constant g.
    rxg = cross(lever, g_hat)
    tau = np.einsum("nji,nji->nj", z, rxg)  # Eq. (21)
    if np.any(prismatic):
        tau[:, prismatic] = z[:, prismatic] @ g_hat
    return tau


def link_torque_basis(
    frames: ChainFrames,
    g_hat: Float,
    shoulder: int,
    elbow: int,
    wrist_frame: int,
    x_sign: float,
    model: str,
) -> Float:
    """Torque on every joint per unit of each link moment, shape (N, n, n_moments).

    The paper's lumped model (Eq. 25-26, Table 1) with moments as vectors:
    ``M_shoulder = s1 x̂ + s2 û`` about the shoulder axis and ``M_elbow = s2 û`` about
    the elbow axis, with ``x̂`` the DH x-axis from the shoulder axis to the elbow axis and
    ``û`` the direction from the elbow axis to the wrist centre (origin of ``wrist_frame``)
    normal to the elbow axis. ``tau_j = z_j · (M_j × ĝ)``.

    Parameters
    ----------
    shoulder, elbow : int
        1-based joints (LR Mate: 2, 3); joint j turns about ``z_{j-1}``.
    wrist_frame : int
        Standard-DH frame whose origin is the wrist centre (LR Mate: 4).
    x_sign : float
        Sign of the shoulder row's ``a`` so ``x̂`` points from shoulder to elbow axis.
    model : {'paper', 'rfcm'}
        'paper': moments ``[s1, s2]`` with s2 shared by both joints (2 columns).
        'rfcm': ``[s1, s2_shoulder, s2_elbow]`` independent (3 columns).
    """
    N, n = frames.o.shape[0], frames.n
    z_sh = frames.z(shoulder - 1)
    z_el = frames.z(elbow - 1)
    x_hat = x_sign * frames.R[:, shoulder, :, 0]
    w = frames.o[:, wrist_frame] - frames.o[:, elbow - 1]
    w = w - np.sum(w * z_el, axis=-1, keepdims=True) * z_el
    u_hat = w / np.linalg.norm(w, axis=-1, keepdims=True)
    # tau = z . (M x g) for a unit moment along each direction
    t_x_sh = np.sum(z_sh * cross(x_hat, g_hat), axis=-1)  # Table 1: s1 on the shoulder
    t_u_sh = np.sum(z_sh * cross(u_hat, g_hat), axis=-1)  # Table 1: s2 on the shoulder
    t_u_el = np.sum(z_el * cross(u_hat, g_hat), axis=-1)  # Table 1: s2 on the elbow
    ncol = 2 if model == "paper" else 3
    out = np.zeros((N, n, ncol))
    out[:, shoulder - 1, 0] = t_x_sh
    if model == "paper":
        out[:, shoulder - 1, 1] = t_u_sh  # Eq. (25): N_23(theta) (s1, s2, s2)
        out[:, elbow - 1, 1] = t_u_el
    else:
        out[:, shoulder - 1, 1] = t_u_sh
        out[:, elbow - 1, 2] = t_u_el
    return out


def general_link_names(bodies: tuple[int, ...]) -> list[str]:
    """Parameter names of the general link model: mass and first moment per body."""
    return [f"link{k}.{c}" for k in bodies for c in ("m", "mx", "my", "mz")]


def general_link_torque_basis(
    frames: ChainFrames, g_hat: Float, bodies: tuple[int, ...], prismatic: np.ndarray
) -> Float:
    """Torque on every joint per unit of each body's mass and first moment (N, n, 4 nb).

    The general form of Eq. (25) for any serial robot and any base tilt: body k (rigid
    with DH frame k) has mass ``m_k`` and first moment ``m_k c_k`` (frame k axes), both per
    unit payload weight. Joint j <= k carries
    ``tau_j = z_{j-1} · ((R_k (m c)_k + m_k (o_k - o_{j-1})) × ĝ)``.
    """
    N, n = frames.o.shape[0], frames.n
    out = np.zeros((N, n, 4 * len(bodies)))
    z = frames.R[:, :-1, :, 2]  # (N, n, 3)
    for b, k in enumerate(bodies):
        Rk = frames.R[:, k]
        for j in range(k):  # joints 1..k move body k
            zj = z[:, j]
            if prismatic[j]:
                out[:, j, 4 * b] = (
                    zj @ g_hat
                )  # a force along the axis; moments give none
                continue
            lever = frames.o[:, k] - frames.o[:, j]
            out[:, j, 4 * b] = np.sum(zj * cross(lever, g_hat), axis=-1)
            for c in range(3):
                out[:, j, 4 * b + 1 + c] = np.sum(
                    zj * cross(Rk[:, :, c], g_hat), axis=-1
                )
    return out


def _moved(first: np.ndarray, k: int) -> np.ndarray:
    """(K,) bool: frame k moves under each parameter's twist (frames >= first move)."""
    return k >= first


def torque_derivatives(
    frames: ChainFrames,
    p_load: Float,
    g_hat: Float,
    prismatic: np.ndarray,
    omega: Float,
    vel: Float,
    first: np.ndarray,
    load_scale: Float,
    link: tuple[str, tuple[int, int, int], float, Float] | None = None,
    bodies: tuple[tuple[int, ...], Float] | None = None,
) -> Float:
    """Derivative of every joint torque w.r.t. K geometric parameters, shape (N, n, K).

    Each parameter moves the frames ``first_k .. n`` (and the load point) by an
    infinitesimal rigid motion ``x -> x + omega × x + vel`` (base frame). For the load
    torque of a revolute joint j with lever ``r = p_load - o_{j-1}``:

    * axis not moved: ``d tau_j = (omega × p_load + vel) · (ĝ × z_{j-1})``;
    * axis moved: ``d tau_j = (z_{j-1} × r) · (ĝ × omega)`` (Jacobi identity).

    Link-weight torques ``z · (M × ĝ)`` follow from the motion of their axes and moment
    directions the same way.

    Parameters
    ----------
    omega, vel : (N, K, 3) twist of each parameter (base frame).
    first : (K,) int, first frame moved (n + 1: only the load point moves).
    load_scale : (N,) payload scale per row.
    link : ('paper' | 'rfcm', (shoulder, elbow, wrist_frame), x_sign, moments) or None.
    bodies : (body numbers, coefficients (4 per body)) of the general link terms, or None.
    """
    n = frames.n
    Z = frames.R[:, :n, :, 2]  # (N, n, 3) joint axes
    gb = np.broadcast_to(g_hat, Z.shape)
    zr = cross(Z, p_load[:, None, :] - frames.o[:, :n])  # z × lever
    gz = cross(gb, Z)  # ĝ × z
    # All joints at once as batched products (N, K, 3) @ (N, 3, n), the triple
    # products rearranged so no (N, K, 3) cross product is formed:
    # (omega × p + vel) · (ĝ × z) = omega · (p × (ĝ × z)) + vel · (ĝ × z), and
    # (ĝ × omega) · (z × r) = omega · ((z × r) × ĝ).
    pgz = cross(np.broadcast_to(p_load[:, None, :], Z.shape), gz)
    up = omega @ pgz.transpose(0, 2, 1) + vel @ gz.transpose(0, 2, 1)
    down = omega @ cross(zr, gb).transpose(0, 2, 1)
    moved = np.arange(n)[None, :] >= first[:, None]  # (K, n): axis j moved by k
    res = np.where(moved[None], down, up)
    if np.any(prismatic):
        # A force along the axis: only the axis direction matters, (omega × z) · ĝ.
        zg = cross(Z, np.broadcast_to(g_hat, Z.shape))
        along = np.where(moved[None], omega @ zg.transpose(0, 2, 1), 0.0)
        res = np.where(np.asarray(prismatic, bool)[None, None, :], along, res)
    out = np.ascontiguousarray(res.transpose(0, 2, 1))  # (N, n, K)
    out *= load_scale[:, None, None]
    if link is not None:
        out += _link_derivatives(frames, g_hat, omega, vel, first, *link)
    if bodies is not None:
        out += _body_derivatives(frames, g_hat, prismatic, omega, vel, first, *bodies)
    return out


def _link_derivatives(
    frames: ChainFrames,
    g_hat: Float,
    omega: Float,
    vel: Float,
    first: np.ndarray,
    model: str,
    joints: tuple[int, int, int],
    x_sign: float,
    s: Float,
) -> Float:
    sh, el, wf = joints
    N, n = frames.o.shape[0], frames.n
    K = omega.shape[1]
    z_sh = frames.z(sh - 1)
    z_el = frames.z(el - 1)
    x_hat = x_sign * frames.R[:, sh, :, 0]
    o_wf = frames.o[:, wf]
    w = o_wf - frames.o[:, el - 1]
    w_p = w - np.sum(w * z_el, axis=-1, keepdims=True) * z_el
    norm = np.linalg.norm(w_p, axis=-1, keepdims=True)
    u_hat = w_p / norm
    gb = np.broadcast_to(g_hat, z_sh.shape)
    m_sh = _moved(first, sh - 1).astype(float)
    m_el = _moved(first, el - 1).astype(float)
    m_x = _moved(first, sh).astype(float)
    m_wf = _moved(first, wf).astype(float)

    def dot(a: Float, v: Float) -> Float:  # (N, K, 3) · (N, 3) -> (N, K)
        return (a @ v[:, :, None])[..., 0]

    # Every term is a triple product with a parameter twist: (omega × a) · b is
    # omega · (a × b), so each reduces to one batched matrix-vector product.
    def du_dot(v: Float) -> Float:
        """du · v, with u following the elbow frame rigidly, or turning as the wrist
        centre alone moves (du = P_u P_z dw / |w_p|, P the projections)."""
        rigid = dot(omega, cross(u_hat, v))
        pv = v - np.sum(v * u_hat, axis=-1, keepdims=True) * u_hat
        pv = (pv - np.sum(pv * z_el, axis=-1, keepdims=True) * z_el) / norm
        free = dot(omega, cross(o_wf, pv)) + dot(vel, pv)
        return m_el * rigid + (1.0 - m_el) * m_wf * free

    xg = cross(x_hat, gb)
    ug = cross(u_hat, gb)
    gz_sh = cross(gb, z_sh)
    gz_el = cross(gb, z_el)
    d_x_sh = m_sh * dot(omega, cross(z_sh, xg)) + m_x * dot(omega, cross(x_hat, gz_sh))
    d_u_sh = m_sh * dot(omega, cross(z_sh, ug)) + du_dot(gz_sh)
    d_u_el = m_el * dot(omega, cross(z_el, ug)) + du_dot(gz_el)
    out = np.zeros((N, n, K))
    if model == "paper":
        out[:, sh - 1] = s[0] * d_x_sh + s[1] * d_u_sh
        out[:, el - 1] = s[1] * d_u_el
    else:
        out[:, sh - 1] = s[0] * d_x_sh + s[1] * d_u_sh
        out[:, el - 1] = s[2] * d_u_el
    return out


def _body_derivatives(
    frames: ChainFrames,
    g_hat: Float,
    prismatic: np.ndarray,
    omega: Float,
    vel: Float,
    first: np.ndarray,
    bodies: tuple[int, ...],
    coef: Float,
) -> Float:
    N, n = frames.o.shape[0], frames.n
    K = omega.shape[1]
    out = np.zeros((N, n, K))
    g = g_hat[None, None, :]

    def motion(k: int) -> Float:  # (N, K, 3) velocity of frame k's origin
        v = cross(omega, frames.o[:, k][:, None, :]) + vel
        return np.where(_moved(first, k)[None, :, None], v, 0.0)

    for b, k in enumerate(bodies):
        m, mc = coef[4 * b], coef[4 * b + 1 : 4 * b + 4]
        Mk = frames.R[:, k] @ mc  # (N, 3) first moment in the base frame
        dMk = np.where(
            _moved(first, k)[None, :, None], cross(omega, Mk[:, None, :]), 0.0
        )
        dok = motion(k)
        for j in range(k):
            z = frames.z(j)
            dz = np.where(
                _moved(first, j)[None, :, None], cross(omega, z[:, None, :]), 0.0
            )
            if prismatic[j]:
                out[:, j] += m * np.sum(dz * g, axis=-1)
                continue
            lever = Mk + m * (frames.o[:, k] - frames.o[:, j])
            dlever = dMk + m * (dok - motion(j))
            out[:, j] += np.sum(dz * cross(lever, g_hat)[:, None, :], -1) + np.sum(
                z[:, None, :] * cross(dlever, g), -1
            )
    return out
