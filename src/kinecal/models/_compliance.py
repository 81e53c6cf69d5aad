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
difference is second order in the deflection (~1e-8 rad). :func:`torque_adjoint`
gives their exact derivatives with respect to the geometry (for the Jacobian).

Arrays keep the pose axis last (vectors ``(..., 3, N)``, torques ``(n, N)``), the layout
of :class:`~kinecal.models.ChainFrames`.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from kinecal.models._chain import ChainFrames, rotate, vcross, vdot
from kinecal.typing import Float

__all__ = [
    "TorqueAdjoint",
    "general_link_pattern",
    "general_link_torque_basis",
    "gravity_columns",
    "link_torque_basis",
    "link_torque_pattern",
    "load_torques",
    "ntm_basis",
    "ntm_basis_rows",
    "ntm_names",
    "torque_adjoint",
]


def gravity_columns(g_hat: Float) -> Float:
    """Unit gravity as pose-last columns: ``(3, 1)`` for one direction (3,), as given for
    one per pose ``(3, N)`` (several user frames, each with its own view of gravity)."""
    g = np.asarray(g_hat, dtype=np.float64)
    return g[:, None] if g.ndim == 1 else g


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
    return np.moveaxis(ntm_basis_rows(q, order, offset), 0, -1)


def ntm_basis_rows(q: Float, order: int, offset: bool) -> Float:
    """The basis of :func:`ntm_basis` with the pose axis last: shape (nb, N), contiguous
    (the model's layout)."""
    q = np.asarray(q, dtype=np.float64)
    out = np.empty((2 * order + int(offset), *q.shape))
    if offset:
        out[0] = 1.0
    c1, s1 = np.cos(q), np.sin(q)
    c, s = c1, s1
    for h in range(1, order + 1):  # Eq. (16); cos and sin of h q by the angle sums
        if h > 1:
            c, s = c * c1 - s * s1, s * c1 + c * s1
        out[int(offset) + 2 * h - 2] = c
        out[int(offset) + 2 * h - 1] = s
    return out


def load_torques(
    frames: ChainFrames, p_load: Float, g_hat: Float, prismatic: np.ndarray
) -> Float:
    """Joint torques of a unit weight along ``g_hat`` acting at ``p_load``, shape (n, N).

    ``tau = J_v^T g_hat`` (Eq. 21 with the wrench of Eq. 19-20 moved to the load point),
    where column j of ``J_v`` is ``z_{j-1} x (p - o_{j-1})`` (revolute) or ``z_{j-1}``
    (prismatic). Units: N·m per N = m.

    Parameters
    ----------
    frames : ChainFrames
    p_load : ndarray, shape (3, N)
        Load point in the chain base frame [m].
    g_hat : ndarray, shape (3,) or (3, N)
        Unit gravity direction in the frame of ``frames`` (one per pose allowed).
    prismatic : ndarray of bool, shape (n,)
    """
    n = frames.n
    z = frames.cols[:n, 2]  # (n, 3, N) joint axes
    g = gravity_columns(g_hat)
    # (z x r) . g == z . (r x g): one cross product with the constant g.
    tau = vdot(z, vcross(p_load - frames.origin[:n], g))  # Eq. (21)
    if np.any(prismatic):
        tau[prismatic] = vdot(z[prismatic], g)
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
    """Torque on every joint per unit of each link moment, shape (n, n_moments, N).

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
    g = gravity_columns(g_hat)
    z_sh, z_el = frames.z(shoulder - 1), frames.z(elbow - 1)
    x_hat = x_sign * frames.cols[shoulder, 0]
    u_hat = _elbow_to_wrist(frames, elbow, wrist_frame)[0]
    (_, c_x), (_, c_u_sh), (_, c_u_el) = link_torque_pattern(model, shoulder, elbow)
    out = np.zeros((frames.n, 2 if model == "paper" else 3, z_sh.shape[-1]))
    # tau = z . (M x g) for a unit moment along each direction
    # Table 1: s1 and s2 on the shoulder
    out[shoulder - 1, c_x] = vdot(z_sh, vcross(x_hat, g))
    out[shoulder - 1, c_u_sh] = vdot(z_sh, vcross(u_hat, g))
    # Eq. (25): N_23(theta) (s1, s2, s2) for 'paper'; s2 of the elbow its own for 'rfcm'
    out[elbow - 1, c_u_el] = vdot(z_el, vcross(u_hat, g))
    return out


def link_torque_pattern(model: str, shoulder: int, elbow: int) -> list[tuple[int, int]]:
    """The entries ``(joint, moment column)`` of :func:`link_torque_basis` that are not
    identically zero: the x̂ moment and the û moment on the shoulder, the û moment on the
    elbow (shared with the shoulder's in 'paper', its own column in 'rfcm')."""
    return [(shoulder, 0), (shoulder, 1), (elbow, 1 if model == "paper" else 2)]


def _elbow_to_wrist(
    frames: ChainFrames, elbow: int, wrist_frame: int
) -> tuple[Float, Float]:
    """Unit direction ``û`` (3, N) from the elbow axis to the wrist centre, normal to the
    elbow axis, and the length (N,) of that normal offset."""
    z_el = frames.z(elbow - 1)
    w = frames.origin[wrist_frame] - frames.origin[elbow - 1]
    w = w - vdot(w, z_el) * z_el
    norm = np.sqrt(vdot(w, w))
    return w / norm, norm


def general_link_pattern(
    bodies: tuple[int, ...], prismatic: np.ndarray
) -> list[tuple[int, int]]:
    """The entries ``(joint, column)`` of :func:`general_link_torque_basis` that are not
    identically zero: every joint upstream of a body carries its mass, and a revolute one
    its first moment too."""
    out = []
    for b, k in enumerate(bodies):
        for j in range(k):
            cols = (0,) if prismatic[j] else (0, 1, 2, 3)
            out += [(j + 1, 4 * b + c) for c in cols]
    return out


def general_link_torque_basis(
    frames: ChainFrames, g_hat: Float, bodies: tuple[int, ...], prismatic: np.ndarray
) -> Float:
    """Torque on every joint per unit of each body's mass and first moment (n, 4 nb, N).

    The general form of Eq. (25) for any serial robot and any base tilt: body k (rigid
    with DH frame k) has mass ``m_k`` and first moment ``m_k c_k`` (frame k axes), both per
    unit payload weight. Joint j <= k carries
    ``tau_j = z_{j-1} · ((R_k (m c)_k + m_k (o_k - o_{j-1})) × ĝ)``.
    """
    n, N = frames.n, frames.origin.shape[-1]
    g = gravity_columns(g_hat)
    out = np.zeros((n, 4 * len(bodies), N))
    for b, k in enumerate(bodies):
        for j in range(k):  # joints 1..k move body k
            zj = frames.z(j)
            if prismatic[j]:  # a force along the axis; moments give none
                out[j, 4 * b] = vdot(zj, g)
                continue
            # Eq. (25), general: the mass at o_k and the first moment of body k
            out[j, 4 * b] = vdot(zj, vcross(frames.origin[k] - frames.origin[j], g))
            out[j, 4 * b + 1 : 4 * b + 4] = vdot(zj, vcross(frames.cols[k], g))
    return out


class TorqueAdjoint:
    """The terms of the weighted torque derivatives, keyed by the first moved frame they
    need (see :func:`torque_adjoint`).

    A term ``[f <= t] (omega · w + vel · v)`` on joint j (weight row ``H[j]``, (c, N))
    counts for every twist that moves frames f.. with ``f <= t``. Terms of the same t and
    joint are summed as vectors first; :meth:`sweep` then adds the outer products up from
    the last frame down, so one running pair of (c, 3, N) sums serves every first moved
    frame in turn.
    """

    def __init__(self, H: Float) -> None:
        self.H = H
        self.n = H.shape[0]
        self._vec: dict[tuple[int, int], list[Float | None]] = {}
        self._batch: list[tuple[int, np.ndarray | slice, Float, Float]] = []

    def add(self, t: int, j: int, w: Float | None, v: Float | None = None) -> None:
        """Record ``[f <= t] (omega · w + vel · v)`` on joint j (0-based).

        Terms with t = 0 are dropped: no geometric parameter moves frame 0 relative to
        gravity (the user frame carries gravity along), so no twist has f = 0.
        """
        if t < 1:
            return
        entry = self._vec.setdefault((t, j), [None, None])
        for slot, vec in enumerate((w, v)):
            if vec is not None:
                old = entry[slot]
                entry[slot] = vec if old is None else old + vec

    def add_joints(
        self, t: int, joints: np.ndarray | slice, w: Float, v: Float
    ) -> None:
        """The same for several joints at once: w, v (k, 3, N) for ``joints`` (k indices,
        or a slice of the joints)."""
        self._batch.append((t, joints, w, v))

    def sweep(self) -> Iterator[tuple[int, Float, Float]]:
        """``(f, M_f, V_f)`` for f = n + 1, n, ..., 1, such that for every twist moving
        frames f.. and the load, ``sum_j H_j d tau_j = M_f omega + V_f vel`` ((c, 3, N)
        each). The arrays are updated in place for the next f."""
        shape = (self.H.shape[1], 3, self.H.shape[2])
        M, V = np.zeros(shape), np.zeros(shape)
        for f in range(self.n + 1, 0, -1):
            for t, joints, w, v in self._batch:
                if t == f:
                    M += np.einsum("jcn,jbn->cbn", self.H[joints], w)
                    V += np.einsum("jcn,jbn->cbn", self.H[joints], v)
            for (t, j), vecs in self._vec.items():
                if t == f:
                    for acc, vec in zip((M, V), vecs):
                        if vec is not None:
                            acc += self.H[j][:, None, :] * vec[None]
            yield f, M, V


def torque_adjoint(
    frames: ChainFrames,
    p_load: Float,
    g_hat: Float,
    prismatic: np.ndarray,
    H: Float,
    load_scale: Float,
    link: tuple[str, tuple[int, int, int], float, Float] | None = None,
    bodies: tuple[tuple[int, ...], Float] | None = None,
) -> TorqueAdjoint:
    """Weighted torque derivatives for any rigid motion of the arm's downstream frames.

    A geometric parameter moves the frames ``f .. n`` (and the load point) by an
    infinitesimal rigid motion ``x -> x + omega × x + vel``. :meth:`TorqueAdjoint.sweep`
    of the result yields ``M_f, V_f`` (c, 3, N) such that for every such twist

    .. math:: \\sum_j H_j \\, \\partial\\tau_j = M_f\\,\\omega + V_f\\,v,

    with ``H_j`` (c, N) the weight of joint j's torque (the model uses ``lambda*_j``
    times the output's derivative w.r.t. ``theta_j``). Every torque derivative is a triple
    product with the twist: for the load torque of a revolute joint j, lever
    ``r = p_load - o_{j-1}``,

    * axis not moved: ``d tau_j = (omega × p_load + vel) · (ĝ × z_{j-1})``;
    * axis moved: ``d tau_j = (z_{j-1} × r) · (ĝ × omega)`` (Jacobi identity);

    so each is ``[f <= t] (omega · w + vel · v)`` for a threshold t (the frame the term
    needs moved) and fixed vectors w, v. Summing the terms by threshold makes the cost per
    parameter one 3x3 product, not one dot product per joint.

    Parameters
    ----------
    frames : ChainFrames
    p_load : (3, N) load point.
    g_hat : (3,) or (3, N) unit gravity in the frame of ``frames``.
    prismatic : (n,) bool.
    H : (n, c, N) weight of each joint's torque.
    load_scale : (N,) payload scale per row (multiplies the load torque).
    link : ('paper' | 'rfcm', (shoulder, elbow, wrist_frame), x_sign, moments) or None.
    bodies : (body numbers, coefficients (4 per body)) of the general link terms, or None.
    """
    n = frames.n
    acc = TorqueAdjoint(H)
    g = gravity_columns(g_hat)
    rev = ~np.asarray(prismatic, bool)
    Z = frames.cols[:n, 2]  # (n, 3, N) joint axes
    # The payload scale of each row multiplies the load terms' vectors (it is a scalar
    # per pose), so that every term of a joint shares the weight H_j.
    gz = vcross(g, Z)
    gz *= load_scale
    up_w = vcross(p_load, gz)  # d Eq. (21), axis still: (omega × p + vel) · (ĝ × z)
    down_w = vcross(vcross(Z, p_load - frames.origin[:n]), g)  # axis moved
    down_w *= load_scale
    # Revolute: 'still' always, minus 'still' plus 'moved' once the axis moves.
    # Prismatic (a force along the axis): (omega × z) · ĝ once the axis moves.
    if rev.all():  # views, no gather
        acc.add_joints(n + 1, slice(None), up_w, gz)
    elif rev.any():
        acc.add_joints(n + 1, np.flatnonzero(rev), up_w[rev], gz[rev])
    for i in range(n):
        if rev[i]:
            acc.add(i, i, down_w[i] - up_w[i], -gz[i])
        else:
            acc.add(i, i, vcross(Z[i], g) * load_scale)
    if link is not None:
        _link_terms(acc, frames, g, *link)
    if bodies is not None:
        _body_terms(acc, frames, g, rev, *bodies)
    return acc


def _link_terms(
    acc: TorqueAdjoint,
    frames: ChainFrames,
    g: Float,
    model: str,
    joints: tuple[int, int, int],
    x_sign: float,
    s: Float,
) -> None:
    """Terms of the lumped link torques ``z · (M × ĝ)`` (:func:`link_torque_basis`)."""
    sh, el, wf = joints
    s_x, s_u_sh = s[0], s[1]
    s_u_el = s[1] if model == "paper" else s[2]
    z_sh, z_el = frames.z(sh - 1), frames.z(el - 1)
    x_hat = x_sign * frames.cols[sh, 0]
    o_wf = frames.origin[wf]
    u_hat, norm = _elbow_to_wrist(frames, el, wf)
    ug = vcross(u_hat, g)
    # x̂ moves with frame sh; û turns rigidly with the elbow frame, or (elbow still,
    # wrist centre moved) as du = P_z P_u d(o_wf) / |w_p|, P the projections.
    t_free = min(el - 1, wf)

    def du_terms(j: int, scale: float, v: Float) -> None:
        """``scale · du · v`` on joint j."""
        acc.add(el - 1, j, scale * vcross(u_hat, v))
        pv = v - vdot(v, u_hat) * u_hat
        pv = (pv - vdot(pv, z_el) * z_el) / norm
        w, vv = scale * vcross(o_wf, pv), scale * pv
        acc.add(wf, j, w, vv)  # [moved wf] - [moved el - 1 and wf]
        acc.add(t_free, j, -w, -vv)

    j_sh, j_el = sh - 1, el - 1  # d Eq. (25), Table 1
    acc.add(sh - 1, j_sh, vcross(z_sh, s_x * vcross(x_hat, g) + s_u_sh * ug))
    acc.add(sh, j_sh, s_x * vcross(x_hat, vcross(g, z_sh)))
    du_terms(j_sh, s_u_sh, vcross(g, z_sh))
    acc.add(el - 1, j_el, s_u_el * vcross(z_el, ug))
    du_terms(j_el, s_u_el, vcross(g, z_el))


def _body_terms(
    acc: TorqueAdjoint,
    frames: ChainFrames,
    g: Float,
    rev: np.ndarray,
    bodies: tuple[int, ...],
    coef: Float,
) -> None:
    """Terms of the general link torques (:func:`general_link_torque_basis`)."""
    for b, k in enumerate(bodies):
        m, mc = coef[4 * b], coef[4 * b + 1 : 4 * b + 4]
        Mk = rotate(frames.cols[k], mc)  # first moment, base frame
        ok = frames.origin[k]
        for j in range(k):
            z = frames.z(j)
            if not rev[j]:  # (omega × z) · ĝ m
                acc.add(j, j, m * vcross(z, g))
                continue
            oj = frames.origin[j]
            gz = vcross(g, z)
            lever = Mk + m * (ok - oj)
            # the axis turns; the lever's ends move with frames k and j
            acc.add(j, j, vcross(z, vcross(lever, g)) - m * vcross(oj, gz), -m * gz)
            acc.add(k, j, vcross(Mk + m * ok, gz), m * gz)
