"""The model's forward pass in numpy: joint angles, both chains, torques, the point.

.. math::
    \\theta = C q_{ctrl} + \\delta\\theta_C + \\lambda^* \\odot (\\tau_F + \\tau_{Link}),
    \\qquad p_{user} = T_{user,base} \\prod_i A_i(\\theta_i)\\, (t_{fc} + R_{fc} p_{cam})

The reference implementation of :meth:`~kinecal.models.CalibrationModel.evaluate`
without Jacobians (those are in :mod:`kinecal.models._numpy_jacobian`), reading only the
public :class:`~kinecal.models.ModelDefinition`. Everything keeps the pose axis last:
vectors are (3, N), see :mod:`kinecal.models._chain`. Both chains start at the user frame,
so every point, axis and Jacobian column is in the user frame from the start; the torques
are frame-invariant with gravity mapped along.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import ModelError
from kinecal.models._chain import (
    ChainFrames,
    chain_frames,
    rotate,
    shifted_trig_if_small,
    vcross,
)
from kinecal.models._compliance import (
    general_link_torque_basis,
    link_torque_basis,
    load_torques,
)
from kinecal.models._definition import ALPHA, BETA, OFF, A, D, ModelDefinition
from kinecal.models._inputs import ModelInputs
from kinecal.typing import Float

__all__ = [
    "ForwardState",
    "chain",
    "flange_frames",
    "flange_point",
    "forward",
    "joint_columns",
    "joint_jacobian",
    "link_basis",
    "ntm_errors",
    "row_trig",
    "user_base",
]


@dataclass(frozen=True)
class ForwardState:
    """What a Jacobian needs of a forward evaluation (opaque; see
    :meth:`CalibrationModel.evaluate`). It holds both chains, about 110 numbers a pose."""

    definition: ModelDefinition
    params: Float
    inputs: ModelInputs
    ntm_bases: list[Float]
    t_base: Float
    g: Float
    fr0: ChainFrames | None
    p_load: Float | None
    tau: Float | None
    link_T: Float | None
    fr: ChainFrames
    p_cam_fl: Float
    p_u: Float
    p_user: Float
    R_uc: Float | None
    theta: Float

    def serves(
        self,
        definition: ModelDefinition,
        params: Float,
        inputs: ModelInputs,
        orientation: bool,
    ) -> bool:
        """Whether this state is that of the model of ``definition`` at ``params`` and
        ``inputs``."""
        return (
            self.definition is definition
            and self.inputs is inputs
            and (self.R_uc is not None or not orientation)
            and np.array_equal(self.params, params)
        )


def forward(
    defn: ModelDefinition, p: Float, inputs: ModelInputs, orientation: bool
) -> ForwardState:
    """The forward evaluation of :meth:`CalibrationModel.evaluate` (checked inputs), with
    the state its Jacobian needs."""
    q = inputs.q_ctrl
    spec = defn.spec
    n = q.shape[1]
    rows = defn.rows(p)
    coupled = defn.coupled(inputs)
    theta = coupled[0]  # (n, N), kept with the inputs: not modified in place
    ntm_bases: list[Float] = []
    dth_c = None
    if spec.ntm_joints:
        dth_c, ntm_bases = ntm_errors(defn, p, inputs)
        theta = theta + dth_c  # Eq. (13): delta theta_C
    trig = row_trig(defn, rows, coupled, dth_c)

    R_c, t_c = defn.cam_frames(p)
    R_b, t_b = defn.base_frames(p)
    base, g = user_base(defn, R_b, t_b, inputs.set_index)
    tau = link_T = fr0 = p_load = None
    if spec.load:
        fr0 = chain(defn, theta, rows, base, trig)
        # Load point: origin of the first marker's cam frame (Eq. 19 with Delta = 0).
        p_load = fr0.origin[n] + rotate(fr0.cols[n], t_c[0])
        tau = load_torques(fr0, p_load, g, defn.prismatic)  # Eq. (21), (24)
        tau *= inputs.load_scale
        if defn.link_names:
            link_T = link_basis(defn, fr0, g)
            s = p[defn.link_slice]
            tau += np.einsum("jsn,s->jn", link_T, s)  # Eq. (25)
        deflection = p[defn.lam_idx, None] * tau  # Eq. (22), (24), (26)
        th = theta + deflection  # Eq. (13)
        if defn.prismatic.any():  # a prismatic row's angle does not change
            deflection = np.where(defn.prismatic[:, None], 0.0, deflection)
        shifted = shifted_trig_if_small(fr0.cos, fr0.sin, deflection)
        fr = chain(defn, th, rows, base, shifted)
    else:
        th = theta if dth_c is not None else theta.copy()  # not the kept array
        fr = chain(defn, th, rows, base, trig)

    p_fl, p_cam_fl = flange_point(defn, R_c, t_c, inputs)
    p_u = fr.origin[n] + rotate(fr.cols[n], p_fl)  # Eq. (6-7)
    R_uc = None
    if orientation:
        mi = inputs.marker_index
        R_uc = fr.R[:, n] @ (R_c[0] if len(spec.markers) == 1 else R_c[mi])  # Eq. (7)
    return ForwardState(
        definition=defn,
        params=p.copy(),
        inputs=inputs,
        ntm_bases=ntm_bases,
        t_base=t_b,
        g=g,
        fr0=fr0,
        p_load=p_load,
        tau=tau,
        link_T=link_T,
        fr=fr,
        p_cam_fl=p_cam_fl,
        p_u=p_u,
        p_user=np.ascontiguousarray(p_u.T),
        R_uc=R_uc,
        theta=th.T,
    )


def ntm_errors(
    defn: ModelDefinition, params: Float, inputs: ModelInputs
) -> tuple[Float, list[Float]]:
    """NTM joint-angle errors (n, N) and the basis (nb, N) per NTM joint (the bases are
    computed once per inputs object)."""
    N = inputs.q_ctrl.shape[0]
    dth = np.zeros((defn.n_joints, N))
    stack = defn.ntm_bases(inputs)
    nb = len(defn.ntm_terms)
    for k, j in enumerate(defn.spec.ntm_joints):
        coef = params[defn.ntm_start + k * nb : defn.ntm_start + (k + 1) * nb]
        dth[j - 1] += coef @ stack[k]  # Eq. (17)
    return dth, list(stack)


def row_trig(
    defn: ModelDefinition,
    rows: Float,
    coupled: tuple[Float, Float, Float],
    dth: Float | None,
) -> tuple[Float, Float] | None:
    """Cosines and sines (n, N) of the row angles ``C q + offset + dth`` from those of
    ``C q``: the offsets by the angle sums, the small NTM errors ``dth`` by the series of
    ``shifted_trig``. None for arms with prismatic joints or large errors.
    """
    if defn.prismatic.any():
        return None
    _, cq, sq = coupled
    off = rows[:, OFF, None]
    co, so = np.cos(off), np.sin(off)
    ct = cq * co
    ct -= sq * so
    st = sq * co
    st += cq * so
    if dth is not None:
        js = [j - 1 for j in defn.spec.ntm_joints]
        J: list[int] | slice = js
        if js == list(range(js[0], js[-1] + 1)):  # views, no gather
            J = slice(js[0], js[-1] + 1)
        shifted = shifted_trig_if_small(ct[J], st[J], dth[J])
        if shifted is None:
            return None
        ct[J], st[J] = shifted
    return ct, st


def link_basis(
    defn: ModelDefinition, frames: ChainFrames, g: Float | None = None
) -> Float:
    """Link-weight torque per unit of each link parameter, (n, n_link, N), for gravity
    ``g`` in the frame of ``frames`` (default: the model base frame's); Eq. (25)."""
    g = defn.g_hat if g is None else g
    spec = defn.spec
    parts = []
    if spec.link in ("paper", "rfcm"):
        sw = defn.self_weight
        if sw is None:  # pragma: no cover - rejected by ModelDefinition.build
            raise ModelError("no self_weight section")
        parts.append(
            link_torque_basis(
                frames,
                g,
                sw.shoulder,
                sw.elbow,
                sw.wrist_frame,
                defn.x_sign,
                spec.link,
            )
        )
    if spec.link_bodies:
        parts.append(
            general_link_torque_basis(frames, g, spec.link_bodies, defn.prismatic)
        )
    return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)


def chain(
    defn: ModelDefinition,
    theta: Float,
    rows: Float,
    base: tuple[Float, Float] | None = None,
    trig: tuple[Float, Float] | None = None,
) -> ChainFrames:
    """Chain frames for kinematic joint values ``theta`` (n, N), in the model base frame
    or in the frame ``base`` places it in (see :func:`chain_frames`). ``trig`` gives the
    cosines and sines of the row angles when the caller has them."""
    pr = defn.prismatic
    if np.any(pr):
        th = rows[:, OFF, None] + np.where(pr[:, None], 0.0, theta)
        d = (rows[:, D, None] + np.where(pr[:, None], theta, 0.0)).T
    else:
        th = rows[:, OFF, None] + theta  # Eq. (10): theta_i + offset
        d = rows[:, D]
    beta = rows[:, BETA] if defn.has_beta else None
    return chain_frames(th.T, d, rows[:, A], rows[:, ALPHA], beta, base, trig)


def user_base(
    defn: ModelDefinition, R_b: Float, t_b: Float, set_index: np.ndarray
) -> tuple[tuple[Float, Float], Float]:
    """Where the chain starts in the user frame (for :func:`chain`) and gravity there:
    one frame and (3,) for a single set, per pose and (3, N) for several."""
    if len(defn.spec.sets) == 1:
        return (R_b[0], t_b[0]), R_b[0] @ defn.g_hat
    R = R_b[set_index]
    return (R, t_b[set_index]), (R @ defn.g_hat).T


def flange_point(
    defn: ModelDefinition, R_c: Float, t_c: Float, inputs: ModelInputs
) -> tuple[Float, Float]:
    """The measured point in the flange frame, and its offset from the cam origin
    (both (3, N)): ``t_fc + R_fc p_cam`` and ``R_fc p_cam`` (Eq. 6, 9)."""
    if len(defn.spec.markers) == 1:
        p_rot = R_c[0] @ inputs.p_cam.T
        return t_c[0][:, None] + p_rot, p_rot
    mi = inputs.marker_index
    p_rot = np.einsum("nij,nj->in", R_c[mi], inputs.p_cam)
    return t_c[mi].T + p_rot, p_rot


def joint_columns(
    defn: ModelDefinition, Z: Float, rot_cols: Float, orientation: bool
) -> Float:
    """``d output / d theta_i`` (n, 3 or 6, N) from the joint axes ``Z`` and the point's
    velocity ``z × (p - o)`` of a unit rotation about each (n, 3, N) (``rot_cols`` itself
    for revolute joints and the position only): the columns of J(theta), Eq. (14), (21)."""
    if not orientation and not defn.prismatic.any():
        return rot_cols
    pr = defn.prismatic[:, None, None]
    G = np.zeros((Z.shape[0], 6 if orientation else 3, Z.shape[-1]))
    G[:, :3] = np.where(pr, Z, rot_cols)
    if orientation:
        G[:, 3:] = np.where(pr, 0.0, Z)
    return G


def flange_frames(defn: ModelDefinition, p: Float, theta: Float) -> tuple[Float, Float]:
    """Flange frames ``(R (N, 3, 3), o (N, 3))`` in the model base at the kinematic
    angles ``theta`` (N, n) of an evaluation (with every error term)."""
    fr = chain(defn, theta.T, defn.rows(p))
    return np.ascontiguousarray(fr.R[:, -1]), np.ascontiguousarray(fr.o[:, -1])


def joint_jacobian(
    defn: ModelDefinition, p: Float, inputs: ModelInputs, theta: Float
) -> Float:
    """Geometric Jacobian (N, 6, n) of the model point at the angles ``theta`` (N, n) of
    an evaluation: rows ``[v; omega]`` in the user frame (see
    :meth:`CalibrationModel.joint_jacobian`)."""
    base, _ = user_base(defn, *defn.base_frames(p), inputs.set_index)
    fr = chain(defn, theta.T, defn.rows(p), base)  # in the user frame
    n = defn.n_joints
    R_c, t_c = defn.cam_frames(p)
    p_fl, _ = flange_point(defn, R_c, t_c, inputs)
    p_u = fr.origin[n] + rotate(fr.cols[n], p_fl)
    Z = fr.cols[:n, 2]
    G = joint_columns(defn, Z, vcross(Z, p_u - fr.origin[:n]), True)
    return np.ascontiguousarray(G.transpose(2, 1, 0))  # (N, 6, n)
