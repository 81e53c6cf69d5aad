"""The calibrated kinematic part as a chain of frames (for URDF) or a DH table.

A calibrated model is ``T_user_cam(q) = T_user_base · prod_i A_i(theta_i) · T_flange_cam``
with rows ``A_i = Rz(theta_i + o_i) Tz(d_i) Tx(a_i) Rx(alpha_i) Ry(beta_i)`` (standard DH,
Hayati where ``beta`` is a parameter; a prismatic joint adds its value to ``d``) and
``theta = C q_ctrl`` plus the compliance and transmission terms. The *kinematic part* is
the same with those terms zero; it is what a URDF or a DH table can hold.

Frames of the exported chain: ``user`` (the measurement frame of one set), ``base`` (the
robot's base frame, placed where the nominal kinematics put it relative to the model's
joint-1 frame), ``link1 .. linkN`` (the model's DH frames: link i turns with joint i),
``flange`` (the physical flange, nominally placed on the last link) and one ``tool`` per
marker (the calibrated cam frame). Joint i's origin is the constant part of row i - 1
followed by ``Rz(o_i)``; it turns about its z axis.

Joint couplings (``theta = C q_ctrl``, FANUC: ``theta3 = J3 + J2``): URDF joints hold one
value each, and a URDF ``mimic`` joint follows one other joint (``multiplier * q +
offset``); it cannot add two. Two ways out, chosen by ``coupling``:

* ``'kinematic'`` (default): the URDF joints ``j1..jN`` take the kinematic angles
  ``theta = C q_ctrl`` (FANUC: ``j3 = J3 + J2``), as the ROS-Industrial FANUC URDFs and
  drivers do.
* ``'mimic'``: the URDF joints take the controller angles; each coupling term
  ``C[i, k] q_k`` becomes a mimic joint ``j{i}_from_j{k}`` (multiplier ``C[i, k]``) on
  joint i's axis just before it, so that the rotations about that axis add up. Needs a
  diagonal of +-1.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal.errors import ConfigError, DataError
from kinecal.geometry import make_transform, rot_x, rot_y, rot_z
from kinecal.measurement import CalibratedModel
from kinecal.measurement._calibrated import label_list
from kinecal.models import ModelInputs
from kinecal.robot import JointSpec, RobotDescription
from kinecal.typing import Float, Pose

__all__ = [
    "COUPLING_MODES",
    "Element",
    "ExportedChain",
    "GeometryLoss",
    "check_chain",
    "dh_description",
    "export_chain",
    "flange_offset",
    "geometry_loss",
    "has_compliance",
    "kinematic_params",
    "robot_base_offset",
]

COUPLING_MODES = ("kinematic", "mimic")
_COMPLIANCE_GROUPS = ("ntm", "load", "link")
_ROW_KEYS = ("theta_offset", "d", "a", "alpha", "beta")


@dataclass(frozen=True)
class Element:
    """One URDF joint: ``T_parent_child = origin · motion(axis, value)``.

    Attributes
    ----------
    name, parent, child : str
    kind : {'fixed', 'revolute', 'prismatic'}
    origin : (4, 4) the child frame in the parent frame at value 0 [m].
    axis : (3,) unit axis in the child frame.
    limits : (2,) [rad or m] or None.
    mimic : (joint name, multiplier, offset) or None.
    """

    name: str
    kind: str
    parent: str
    child: str
    origin: Pose
    axis: Float = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    limits: Float | None = None
    mimic: tuple[str, float, float] | None = None


@dataclass(frozen=True)
class ExportedChain:
    """A calibrated kinematic part as a tree of frames rooted at ``root``.

    Attributes
    ----------
    elements : the URDF joints, parents before children.
    root : root link ('user').
    joints : names of the actuated joints (j1..jN), in order.
    tips : marker label -> tool link.
    coupling : 'kinematic' or 'mimic' (see the module docstring).
    C : (n, n) coupling matrix of the robot.
    T_user_base : (4, 4) the robot base in the user frame.
    """

    elements: tuple[Element, ...]
    root: str
    joints: tuple[str, ...]
    tips: dict[str, str]
    coupling: str
    C: Float
    T_user_base: Pose

    def joint_values(self, q_ctrl: Float) -> Float:
        """Values (N, n) of ``joints`` for controller values (N, n)."""
        q = np.asarray(q_ctrl, dtype=np.float64)
        return np.asarray(q @ self.C.T) if self.coupling == "kinematic" else q

    def fk(self, q_ctrl: Float, tip: str) -> Pose:
        """Pose (N, 4, 4) of link ``tip`` in ``root`` for controller values (N, n)."""
        q = np.atleast_2d(np.asarray(q_ctrl, dtype=np.float64))
        values = dict(zip(self.joints, self.joint_values(q).T))
        by_child = {e.child: e for e in self.elements}
        path = []
        link = tip
        while link != self.root:
            if link not in by_child:
                raise ValueError(f"link {tip!r} is not below {self.root!r}.")
            path.append(by_child[link])
            link = by_child[link].parent
        T = np.broadcast_to(np.eye(4), (q.shape[0], 4, 4)).copy()
        for e in reversed(path):
            T = T @ e.origin
            if e.kind == "fixed":
                continue
            if e.mimic is not None:
                v = e.mimic[1] * values[e.mimic[0]] + e.mimic[2]
            else:
                v = values[e.name]
            M = np.broadcast_to(np.eye(4), T.shape).copy()
            if e.kind == "prismatic":
                M[:, :3, 3] = v[:, None] * e.axis
            else:
                M[:, :3, :3] = _axis_rotation(e.axis, v)
            T = T @ M
        return T


@dataclass(frozen=True)
class GeometryLoss:
    """How far the kinematic part alone is from the full model on some poses.

    Attributes
    ----------
    n : number of poses.
    rms, max : RMS and largest distance between the two predictions [m].
    """

    n: int
    rms: float
    max: float


def _axis_rotation(axis: Float, angle: Float) -> Float:
    """Rotations (N, 3, 3) by ``angle`` (N,) about the unit ``axis`` (3,) (Rodrigues)."""
    K = np.array(
        [[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]]
    )
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _tz(d: float) -> Pose:
    return make_transform(np.eye(3), [0.0, 0.0, d])


def _row_const(d: float, a: float, alpha: float, beta: float) -> Pose:
    """``Tz(d) Tx(a) Rx(alpha) Ry(beta)``."""
    return _tz(d) @ make_transform(rot_x(alpha) @ rot_y(beta), [a, 0.0, 0.0])


def kinematic_params(cal: CalibratedModel) -> Float:
    """The calibrated parameters with every compliance and transmission term zero: the
    kinematic part of the model (P,)."""
    x = cal.params.copy()
    for group in _COMPLIANCE_GROUPS:
        x[cal.model.layout.group_indices(group)] = 0.0
    return x


def has_compliance(cal: CalibratedModel) -> bool:
    """Whether the model has any non-zero compliance or transmission term."""
    idx = [cal.model.layout.group_indices(g) for g in _COMPLIANCE_GROUPS]
    return bool(np.any(cal.params[np.concatenate(idx)] != 0.0))


def _rows(cal: CalibratedModel) -> Float:
    """Calibrated rows (n, 5): theta_offset, d, a, alpha, beta (0 where not a parameter)."""
    lay = cal.model.layout
    n = cal.model.n_joints
    rows = np.zeros((n, 5))
    for i in range(n):
        for c, key in enumerate(_ROW_KEYS):
            name = f"joint{i + 1}.{key}"
            if name in lay:
                rows[i, c] = cal.params[lay.index(name)]
    return rows


def robot_base_offset(robot: RobotDescription) -> Pose:
    """The model's base (joint-1) frame in the robot's base frame (4, 4): the nominal
    ``T_base_0 · Rz(o_1) Tz(d_1)`` the model absorbs into its user frame."""
    ch = robot.dh_chain()
    return np.asarray(
        ch.T_base_0 @ make_transform(rot_z(ch.theta_offset[0]), [0, 0, ch.d[0]])
    )


def flange_offset(robot: RobotDescription) -> Pose:
    """The physical flange in the model's last link frame (4, 4): the nominal last row's
    constant part and flange, which the model absorbs into its cam frame."""
    ch = robot.dh_chain()
    L = make_transform(rot_z(ch.theta_offset[-1]), [0.0, 0.0, ch.d[-1]])
    L = L @ make_transform(rot_x(ch.alpha[-1]), [ch.a[-1], 0.0, 0.0])
    return np.asarray(L @ ch.T_n_flange)


def _frames(cal: CalibratedModel, x: Float) -> tuple[Float, Float]:
    """``T_user_modelbase`` (S, 4, 4) per set and ``T_flange_cam`` (M, 4, 4) per marker."""
    m = cal.model
    Rb, tb = m.base_frames(x)
    Rc, tc = m.cam_frames(x)
    return make_transform(Rb, tb), make_transform(Rc, tc)


def _set_index(cal: CalibratedModel, label: str | None) -> int:
    sets = cal.model.spec.sets
    if label is None:
        return 0
    if label not in sets:
        raise DataError(
            f"set {label!r} is not in the model (it has {label_list(sets, 'set')})."
        )
    return sets.index(label)


def _link_name(prefix: str, label: str) -> str:
    clean = "".join(ch if ch.isalnum() or ch in "_-" else "_" for ch in label)
    return prefix if label == "" else f"{prefix}_{clean}"


def _coupled_limits(robot: RobotDescription) -> Float:
    """Limits (n, 2) of ``theta = C q`` over the controller box (the widest interval)."""
    C, lim = robot.coupling, robot.limits
    with np.errstate(invalid="ignore"):  # 0 * inf where a joint has no limits
        lo = np.where(C > 0, C * lim[:, 0], C * lim[:, 1])
        hi = np.where(C > 0, C * lim[:, 1], C * lim[:, 0])
    lo = np.where(C == 0, 0.0, lo).sum(axis=1)
    hi = np.where(C == 0, 0.0, hi).sum(axis=1)
    return np.column_stack([lo, hi])


def export_chain(
    cal: CalibratedModel, *, set_label: str | None = None, coupling: str = "kinematic"
) -> ExportedChain:
    """The kinematic part of ``cal`` as a URDF-ready chain rooted at ``user``.

    Parameters
    ----------
    cal : CalibratedModel
    set_label : the set whose user frame is the root (default the first); the user frames
        of the other sets become fixed links ``user_<label>`` under ``base``.
    coupling : 'kinematic' or 'mimic' (module docstring).

    Raises
    ------
    ConfigError
        'mimic' for a coupling matrix without a +-1 diagonal.
    """
    if coupling not in COUPLING_MODES:
        raise ConfigError(
            f"coupling must be one of {COUPLING_MODES}; got {coupling!r}."
        )
    model = cal.model
    robot = model.robot
    n = model.n_joints
    C = robot.coupling
    s = _set_index(cal, set_label)
    x = kinematic_params(cal)
    T_user_mb, T_fc = _frames(cal, x)
    P0 = robot_base_offset(robot)
    T_user_base = T_user_mb[s] @ np.linalg.inv(P0)
    rows = _rows(cal)
    pris = robot.prismatic
    if coupling == "mimic" and not np.allclose(np.abs(np.diag(C)), 1.0):
        raise ConfigError(
            f"{robot.name}: --coupling mimic needs a coupling matrix with +-1 on its "
            "diagonal; use --coupling kinematic."
        )
    theta_lim = robot.limits if coupling == "mimic" else _coupled_limits(robot)
    els: list[Element] = [Element("base_joint", "fixed", "user", "base", T_user_base)]
    for k, label in enumerate(model.spec.sets):
        if k != s:
            T_base_userk = P0 @ np.linalg.inv(T_user_mb[k])
            els.append(
                Element(
                    f"{_link_name('user', label)}_joint",
                    "fixed",
                    "base",
                    _link_name("user", label),
                    T_base_userk,
                )
            )
    parent, const = "base", P0
    for i in range(n):
        o, d, a, al, be = rows[i]
        kind = "prismatic" if pris[i] else "revolute"
        origin = const @ make_transform(rot_z(o), [0.0, 0.0, 0.0])
        if pris[i]:
            origin = origin @ _tz(d)
            const = _row_const(0.0, a, al, be)
        else:
            const = _row_const(d, a, al, be)
        name, axis = f"j{i + 1}", np.array([0.0, 0.0, 1.0])
        if coupling == "mimic":
            for k in map(int, np.flatnonzero((C[i] != 0) & (np.arange(n) != i))):
                mname = f"j{i + 1}_from_j{k + 1}"
                els.append(
                    Element(
                        mname,
                        kind,
                        parent,
                        f"{mname}_link",
                        origin,
                        axis,
                        np.sort(C[i, k] * robot.limits[k]),
                        (f"j{k + 1}", float(C[i, k]), 0.0),
                    )
                )
                parent, origin = f"{mname}_link", np.eye(4)
            axis = axis * np.sign(C[i, i])
        els.append(
            Element(name, kind, parent, f"link{i + 1}", origin, axis, theta_lim[i])
        )
        parent = f"link{i + 1}"
    F = flange_offset(robot)
    els.append(Element("flange_joint", "fixed", parent, "flange", const @ F))
    tips = {}
    for m, label in enumerate(model.spec.markers):
        tip = _link_name("tool", label)
        tips[label] = tip
        els.append(
            Element(f"{tip}_joint", "fixed", "flange", tip, np.linalg.inv(F) @ T_fc[m])
        )
    joints = tuple(f"j{i + 1}" for i in range(n))
    return ExportedChain(
        tuple(els), "user", joints, tips, coupling, C.copy(), T_user_base
    )


def check_chain(
    cal: CalibratedModel, chain: ExportedChain, set_label: str | None, q_ctrl: Float
) -> float:
    """Largest distance [m] (or angle [rad] times 1 m) between the chain's tool frames and
    the model's kinematic part at ``q_ctrl`` (N, n), over every marker."""
    s = _set_index(cal, set_label)
    x = kinematic_params(cal)
    worst = 0.0
    N = q_ctrl.shape[0]
    for m, label in enumerate(cal.model.spec.markers):
        inp = ModelInputs.make(
            q_ctrl, set_index=np.full(N, s), marker_index=np.full(N, m)
        )
        out = cal.model.evaluate(x, inp, orientation=True)
        assert out.R_user_cam is not None
        T = chain.fk(q_ctrl, chain.tips[label])
        worst = max(
            worst,
            float(np.abs(T[:, :3, 3] - out.p_user).max()),
            float(np.abs(T[:, :3, :3] - out.R_user_cam).max()),
        )
    return worst


def geometry_loss(cal: CalibratedModel, inputs: ModelInputs) -> GeometryLoss:
    """Distance between the full model's and its kinematic part's predictions at the
    poses of ``inputs`` (what a URDF or DH table cannot hold)."""
    full = cal.model.evaluate(cal.params, inputs).p_user
    geo = cal.model.evaluate(kinematic_params(cal), inputs).p_user
    d = np.linalg.norm(full - geo, axis=1)
    return GeometryLoss(int(d.size), float(np.sqrt(np.mean(d**2))), float(d.max()))


def _dh_split(K: Pose) -> tuple[float, float, float, float, float, float]:
    """``K = Rz(delta) Tz(d) Tx(a) Rx(alpha) · Tz(s) Rz(gamma)``: the standard DH numbers
    (delta, d, a, alpha) from the z axis of K's parent to K's z axis along their common
    normal, and what is left along and about K's z axis (s, gamma).

    Nearly parallel axes have a far common normal (large d and s of opposite signs): the
    DH table is then exact but ill-conditioned, as DH is for parallel axes.
    """
    p, u = K[:3, 3], K[:3, 2]
    c = np.array([-u[1], u[0], 0.0])  # e_z x u
    sn = float(np.linalg.norm(c))
    if sn > 1e-12:
        x = c / sn
        # Feet of the common normal: t0 e_z on the first axis, p + t1 u on the second.
        A = np.array([[1.0, -(u[2])], [u[2], -1.0]])
        b = np.array([p[2], p @ u])
        t0, t1 = np.linalg.solve(A, b)
        o = p + t1 * u
        d = float(t0)
    else:  # parallel: the common normal through the parent's origin
        o = p - (p[2] / u[2]) * u
        no = float(np.linalg.norm(o))
        x = o / no if no > 1e-12 else np.array([1.0, 0.0, 0.0])
        d = 0.0
    delta = float(np.arctan2(x[1], x[0]))
    a = float((o - np.array([0.0, 0.0, d])) @ x)
    alpha = float(np.arctan2(np.cross([0.0, 0.0, 1.0], u) @ x, u[2]))
    s_ = float((p - o) @ u)
    xk = K[:3, 0]
    gamma = float(np.arctan2(np.cross(x, xk) @ u, x @ xk))
    return delta, d, a, alpha, s_, gamma


def dh_description(
    cal: CalibratedModel, *, set_label: str | None = None, marker: str | None = None
) -> tuple[RobotDescription, Pose]:
    """The kinematic part as a robot description (the robot's own convention, DH or MDH)
    and the robot base in the user frame of ``set_label`` (4, 4).

    The nominal last row and flange are kept; the calibrated cam frame of ``marker``
    becomes the tool. A Hayati row becomes the DH row of the same axis line (exact; for
    nearly parallel axes its common normal is far away and d large).
    """
    model = cal.model
    robot = model.robot
    n = model.n_joints
    ch = robot.dh_chain()
    markers = model.spec.markers
    if marker is not None and marker not in markers:
        raise DataError(
            f"marker {marker!r} is not in the model (it has "
            f"{label_list(markers, 'marker')})."
        )
    m = 0 if marker is None else markers.index(marker)
    s = _set_index(cal, set_label)
    x = kinematic_params(cal)
    T_user_mb, T_fc = _frames(cal, x)
    rows = _rows(cal)
    rows[0, 0] += ch.theta_offset[0]
    rows[0, 1] += ch.d[0]
    for i in range(n - 1):
        if rows[i, 4] != 0.0:
            K = _row_const(rows[i, 1], *rows[i, 2:5])
            delta, d, a, al, s_, gamma = _dh_split(K)
            rows[i, :5] = rows[i, 0] + delta, d, a, al, 0.0
            rows[i + 1, 0] += gamma
            rows[i + 1, 1] += s_
    gamma_n, s_n = rows[n - 1, 0], rows[n - 1, 1]  # left over from row n - 1
    rows[n - 1, :4] = ch.theta_offset[-1], ch.d[-1], ch.a[-1], ch.alpha[-1]
    L = _row_const(rows[n - 1, 1], rows[n - 1, 2], rows[n - 1, 3], 0.0)
    tool = (
        np.linalg.inv(L @ robot.T_n_flange)
        @ make_transform(rot_z(gamma_n - rows[n - 1, 0]), [0.0, 0.0, s_n])
        @ T_fc[m]
    )
    if robot.convention == "mdh":  # regroup: MDH row i takes a, alpha of DH row i - 1
        a_prev = np.concatenate([[robot.joints[0].a], rows[:-1, 2]])
        al_prev = np.concatenate([[robot.joints[0].alpha], rows[:-1, 3]])
        rows[:, 2], rows[:, 3] = a_prev, al_prev
    joints = tuple(
        JointSpec(
            j.name,
            theta_offset=float(rows[i, 0]),
            d=float(rows[i, 1]),
            a=float(rows[i, 2]),
            alpha=float(rows[i, 3]),
            kind=j.kind,
            limits=j.limits,
            velocity=j.velocity,
            effort=j.effort,
        )
        for i, j in enumerate(robot.joints)
    )
    desc = RobotDescription(
        name=f"{robot.name}-calibrated",
        convention=robot.convention,
        joints=joints,
        coupling=robot.coupling.copy(),
        T_flange_tool=tool,
        T_n_flange=robot.T_n_flange.copy(),
        gravity=robot.gravity.copy(),
        payload_kg=robot.payload_kg,
        self_weight=robot.self_weight,
        source=f"kinematic part of a calibrated {robot.name}",
        prior_sigma=dict(robot.prior_sigma),
        T_base_0=robot.T_base_0.copy(),  # T_user_base is the robot's base
    )
    T_user_base = T_user_mb[s] @ np.linalg.inv(robot_base_offset(robot))
    return desc, T_user_base
