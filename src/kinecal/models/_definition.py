"""The calibration model's definition: its parameters and the tables that place them.

.. math::
    p_{user} = T_{user,base}\\; \\prod_{i=1}^{n} A_i(\\theta_i)\\; T_{flange,cam}\\; p_{cam},
    \\qquad \\theta = C q_{ctrl} + \\delta\\theta_C + \\delta\\theta_F + \\delta\\theta_{Link}

:class:`ModelDefinition` is everything the model's two evaluators read (the numpy code of
:mod:`kinecal.models._numpy_forward` and :mod:`kinecal.models._numpy_jacobian`, the
compiled kernel of :mod:`kinecal.models._kernel`): the parameter layout with its nominal
values, and where each parameter goes. ``T_user_base`` and ``T_flange_cam`` are Euler
frames (Eq. 8, 9) per set and per marker; row i of the chain is
``Rz(theta_i + offset) Tz(d) Tx(a) Rx(alpha) Ry(beta)`` (Eq. 10; ``beta`` only in Hayati
rows), where row 1 keeps only ``a1, alpha1`` and row n only its rotation: 6 + 2 + 4 (n - 2)
+ 6 parameters, 30 for six joints, 27 when the cam rotation is not observable. Then the
compliance terms (:mod:`kinecal.models._compliance`): Fourier coefficients (Eq. 16-17),
lambda* per joint (Eq. 24) and the link self-weight terms (Eq. 25-26).

Symbols: ``q_ctrl`` controller angles (N, n) [rad]; ``theta`` kinematic angles; ``p_cam``
the measured point in the cam frame; ``C`` the robot's joint coupling.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from kinecal._record import ReprRecord
from kinecal.errors import ModelError
from kinecal.geometry import (
    euler_zyx_to_matrix,
    matrix_to_euler_zyx,
)
from kinecal.models._chain import chain_frames
from kinecal.models._compliance import (
    ntm_basis_rows,
)
from kinecal.models._inputs import ModelInputs
from kinecal.models._layout import ParameterLayout
from kinecal.models._parameters import (
    FRAME_FIELDS,
    ROW_FIELDS,
    Params,
    base_frames,
    cam_frames,
    check_terms,
    compliance_terms,
    joint_rows,
    link_pattern,
)
from kinecal.models._spec import ModelSpec
from kinecal.robot import RobotDescription, SelfWeightSpec, dh_transforms
from kinecal.typing import Float

__all__ = [
    "FRAME_FIELDS",
    "ROW_FIELDS",
    "ModelDefinition",
    "euler_axes",
]

OFF, D, A, ALPHA, BETA = range(5)


def euler_axes(R_ref: Float, rwp: Float) -> Float:
    """Rotation axes (columns r, w, p) of ``R_ref Rz(r) Ry(w) Rx(p)`` in the parent frame.

    ``R_ref`` (3, 3) is the frame's fixed reference rotation, ``rwp`` (3,) its Euler angles
    [rad]; the columns are the derivatives of the rotation (Eq. 8-9) by each angle, as
    angular velocities in the parent frame.
    """
    r, w = rwp[0], rwp[1]
    Rz = euler_zyx_to_matrix(np.array([r, 0.0, 0.0]))
    Rzy = euler_zyx_to_matrix(np.array([r, w, 0.0]))
    return np.stack([R_ref[:, 2], (R_ref @ Rz)[:, 1], (R_ref @ Rzy)[:, 0]], axis=1)


def _frame_axes(R_ref: Float, rwp: Float) -> Float:
    """:func:`euler_axes` of K frames at once: ``R_ref`` (K, 3, 3), ``rwp`` (K, 3)."""
    r, w = rwp[:, 0], rwp[:, 1]
    cr, sr, cw, sw = np.cos(r), np.sin(r), np.cos(w), np.sin(w)
    # The y axis of Rz(r) and the x axis of Rz(r) Ry(w), turned by R_ref.
    e_w = np.stack([-sr, cr, np.zeros_like(r)], axis=1)
    e_p = np.stack([cr * cw, sr * cw, -sw], axis=1)
    out = np.empty((len(rwp), 3, 3))
    out[:, :, 0] = R_ref[:, :, 2]
    out[:, :, 1] = np.einsum("kij,kj->ki", R_ref, e_w)
    out[:, :, 2] = np.einsum("kij,kj->ki", R_ref, e_p)
    return out


@dataclass(frozen=True, eq=False, repr=False)
class ModelDefinition(ReprRecord):
    """A calibration model's parameters and the index tables its evaluators read.

    Built by :meth:`build` (what :class:`~kinecal.models.CalibrationModel` does); frozen,
    its arrays read-only. Indices are positions in the flat parameter vector of
    :attr:`layout`; -1 marks a parameter a row does not have.

    Attributes
    ----------
    robot : RobotDescription
    spec : ModelSpec
    layout : ParameterLayout
    nominal : ndarray, shape (P,)
        Parameters reproducing the robot's nominal kinematics with the user frame equal to
        the robot base frame and the compliance terms zero [SI].
    T_robotbase_modelbase : ndarray, shape (4, 4)
        The model's base frame (the robot base with joint 1's absorbed offset and d) in
        the robot description's base frame [m].
    g_hat : ndarray, shape (3,)
        Unit gravity direction in the model base frame.
    prismatic : ndarray of bool, shape (n,)
    row_const : ndarray, shape (n, 5)
        Row values (offset, d, a, alpha, beta) that are not parameters (zeros).
    row_idx : ndarray of int, shape (n, 5)
        Parameter of each row value, -1 for none (Eq. 10: row 1 has a, alpha only; row n
        none; a Hayati row beta instead of d).
    row_mask : ndarray of bool, shape (n, 5)
        ``row_idx >= 0``.
    has_beta : bool
        Some row is a Hayati row.
    cam_keys : tuple of str
        Fields of each cam frame: ``x y z r w p``, or ``x y z`` without the cam rotation.
    base_idx : ndarray of int, shape (S, 6)
        Parameters ``x y z r w p`` of the user frame of each set (Eq. 8).
    cam_idx : ndarray of int, shape (M, 6) or (M, 3)
        Parameters of the cam frame of each marker (Eq. 9), in the order of ``cam_keys``.
    R_ref_base, R_ref_cam : ndarray, shape (S, 3, 3) and (M, 3, 3)
        Fixed reference rotations: a frame is ``Trans(x, y, z) R_ref Rz(r) Ry(w) Rx(p)``.
        The identity (Eq. 8-9 exactly), except the nominal cam rotation when the cam
        rotation is not a parameter.
    ntm_terms : tuple of str
        Coefficient names of one Fourier series (``k0 ka1 kb1 ...``; empty without NTM).
    ntm_start : int
        First NTM parameter: joint ``spec.ntm_joints[k]`` has
        ``ntm_start + k nb .. ntm_start + (k + 1) nb``, nb = ``len(ntm_terms)``.
    load_start : int
        First lambda* parameter (joints 1..n follow; the layout size without load).
    lam_idx : ndarray of int, shape (n,) or (0,)
        The lambda* parameter of each joint (none without the load term).
    link_start : int
        First link parameter.
    link_names : tuple of str
        Names of the link parameters: the lumped moments first (``link.s1`` ...), then 4
        per general body (``link{k}.m, .mx, .my, .mz``).
    self_weight : SelfWeightSpec or None
        The robot's lumped self-weight joints (shoulder, elbow, wrist frame).
    x_sign : float
        Sign of the shoulder row's ``a``: ``x̂`` points from the shoulder axis to the
        elbow axis (lumped link model; 1 otherwise).
    products : tuple of (int, int)
        ``(joint index (0-based), link column)`` of every link parameter and joint it
        loads: the deflection holds the product ``lambda*_j s_k`` (Eq. 26).
    """

    robot: RobotDescription
    spec: ModelSpec
    layout: ParameterLayout
    nominal: Float
    T_robotbase_modelbase: Float
    g_hat: Float
    prismatic: np.ndarray
    row_const: Float
    row_idx: np.ndarray
    row_mask: np.ndarray
    has_beta: bool
    cam_keys: tuple[str, ...]
    base_idx: np.ndarray
    cam_idx: np.ndarray
    R_ref_base: Float
    R_ref_cam: Float
    ntm_terms: tuple[str, ...]
    ntm_start: int
    load_start: int
    lam_idx: np.ndarray
    link_start: int
    link_names: tuple[str, ...]
    self_weight: SelfWeightSpec | None
    x_sign: float
    products: tuple[tuple[int, int], ...]

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value.flags.writeable = False

    def __setstate__(self, state: dict[str, object]) -> None:
        """Unpickling (a worker process's result): read-only arrays again."""
        self.__dict__.update(state)
        self.__post_init__()

    # ------------------------------------------------------------------ construction
    @classmethod
    def build(cls, robot: RobotDescription, spec: ModelSpec) -> ModelDefinition:
        """The definition of ``spec``'s model of ``robot``.

        Raises
        ------
        ModelError
            Terms the robot cannot have (a joint it lacks, a Fourier series on a prismatic
            joint, a Hayati row at non-parallel axes, link terms without self-weight data).
        """
        check_terms(robot, spec)
        n = robot.n_joints
        chain = robot.dh_chain()
        params = Params()
        T_base_b0, base_idx = base_frames(chain, spec, params)
        row_idx, d_shift = joint_rows(chain, spec, params)
        T_fc, cam_keys, cam_idx = cam_frames(robot, chain, spec, d_shift, params)
        # Reference rotations (fixed): identity for identified rotations; the nominal
        # rotation when the cam rotation is not identified.
        R_ref_base = np.broadcast_to(np.eye(3), (len(spec.sets), 3, 3)).copy()
        R_cam_fixed = T_fc[:3, :3] if not spec.cam_rotation else np.eye(3)
        R_ref_cam = np.broadcast_to(R_cam_fixed, (len(spec.markers), 3, 3)).copy()
        ntm_terms, ntm_start, load_start, link_start = compliance_terms(spec, n, params)
        link_names = tuple(s.name for s in params.specs[link_start:])
        # Gravity direction in the model base frame (the robot base rotated by joint 1's
        # absorbed offset).
        g_unit = robot.gravity / np.linalg.norm(robot.gravity)
        sw = robot.self_weight
        x_sign, pattern = link_pattern(robot, chain, spec, len(link_names))
        defn = cls(
            robot=robot,
            spec=spec,
            layout=ParameterLayout(params.specs),
            nominal=np.array(params.nominal),
            T_robotbase_modelbase=T_base_b0,
            g_hat=T_base_b0[:3, :3].T @ g_unit,
            prismatic=chain.prismatic.copy(),
            row_const=np.zeros((n, 5)),
            row_idx=row_idx,
            row_mask=row_idx >= 0,
            has_beta=bool(np.any(row_idx[:, BETA] >= 0)),
            cam_keys=cam_keys,
            base_idx=np.array(base_idx),
            cam_idx=np.array(cam_idx),
            R_ref_base=R_ref_base,
            R_ref_cam=R_ref_cam,
            ntm_terms=ntm_terms,
            ntm_start=ntm_start,
            load_start=load_start,
            lam_idx=(
                np.arange(load_start, load_start + n)
                if spec.load
                else np.zeros(0, np.intp)
            ),
            link_start=link_start,
            link_names=link_names,
            self_weight=sw,
            x_sign=x_sign,
            products=tuple((j - 1, k) for j, k in pattern),
        )
        if spec.link_bodies and robot.link_masses:
            defn = dataclasses.replace(defn, nominal=_link_mass_nominal(defn))
        return defn

    def with_references(
        self, R_ref_base: Float | None = None, R_ref_cam: Float | None = None
    ) -> ModelDefinition:
        """A copy with other fixed reference rotations (None: keep), shaped as these."""
        R_b, R_c = self.R_ref_base, self.R_ref_cam
        if R_ref_base is not None:
            R_b = np.array(R_ref_base, dtype=np.float64).reshape(R_b.shape)
        if R_ref_cam is not None:
            if not self.spec.cam_rotation:
                raise ModelError(
                    "the cam rotation is fixed in this model (cam_rotation=False)."
                )
            R_c = np.array(R_ref_cam, dtype=np.float64).reshape(R_c.shape)
        return dataclasses.replace(self, R_ref_base=R_b, R_ref_cam=R_c)

    # ------------------------------------------------------------------ sizes
    @property
    def size(self) -> int:
        """Number of parameters P."""
        return self.layout.size

    @property
    def n_joints(self) -> int:
        return self.robot.n_joints

    @property
    def n_lumped(self) -> int:
        """Lumped link moments (``link.s1`` ...): the first link parameters."""
        return len(self.link_names) - 4 * len(self.spec.link_bodies)

    @property
    def ntm_slice(self) -> slice:
        """The NTM parameters, every joint's series in turn."""
        nb = len(self.ntm_terms)
        return slice(self.ntm_start, self.ntm_start + len(self.spec.ntm_joints) * nb)

    @property
    def link_slice(self) -> slice:
        """The link parameters."""
        return slice(self.link_start, self.link_start + len(self.link_names))

    @property
    def link_products(self) -> list[tuple[int, int]]:
        """Pairs ``(index of lambda*_j, index of s_k)`` of :attr:`products` (Eq. 26)."""
        return [(int(self.lam_idx[j]), self.link_start + k) for j, k in self.products]

    # ------------------------------------------------------------------ parameters
    def rows(self, params: Float) -> Float:
        """Row values (n, 5): offset, d, a, alpha, beta of each row (Eq. 10)."""
        rows = self.row_const.copy()
        rows[self.row_mask] = params[self.row_idx[self.row_mask]]
        return rows

    def base_frames(self, params: Float) -> tuple[Float, Float]:
        """User frames ``(R_user_base (S, 3, 3), t_user_base (S, 3))`` of every set."""
        v = params[self.base_idx]  # (S, 6)
        R = self.R_ref_base @ euler_zyx_to_matrix(v[:, 3:])  # Eq. (8)
        return R, v[:, :3].copy()

    def cam_frames(self, params: Float) -> tuple[Float, Float]:
        """Cam frames ``(R_flange_cam (M, 3, 3), t_flange_cam (M, 3))`` of every marker."""
        v = params[self.cam_idx]
        if self.spec.cam_rotation:
            R = self.R_ref_cam @ euler_zyx_to_matrix(v[:, 3:])  # Eq. (9)
        else:
            R = self.R_ref_cam.copy()
        return R, v[:, :3].copy()

    def frame_euler(self, params: Float, which: str) -> Float:
        """Total Euler values ``[x, y, z, r, w, p]`` (K, 6) of 'base' or 'cam' frames."""
        R, t = self.base_frames(params) if which == "base" else self.cam_frames(params)
        return np.concatenate([t, matrix_to_euler_zyx(R)], axis=1)

    def base_axes(self, params: Float) -> Float:
        """:func:`euler_axes` of every user frame, (S, 3, 3)."""
        return _frame_axes(self.R_ref_base, params[self.base_idx][:, 3:])

    def cam_axes(self, params: Float) -> Float:
        """:func:`euler_axes` of every cam frame, (M, 3, 3) (with the cam rotation)."""
        return _frame_axes(self.R_ref_cam, params[self.cam_idx][:, 3:])

    # ------------------------------------------------------------------ poses alone
    def coupled(self, inputs: ModelInputs) -> tuple[Float, Float, Float]:
        """Kinematic angles ``C q_ctrl`` (n, N) of the inputs, with their cosines and
        sines (computed once per inputs object)."""
        C = self.robot.coupling

        def make() -> tuple[Float, Float, Float]:
            th = C @ inputs.q_ctrl.T
            return th, np.cos(th), np.sin(th)

        return inputs.derived(("coupled", C.tobytes()), make)

    def ntm_bases(self, inputs: ModelInputs) -> Float:
        """The Fourier bases (Eq. 16) of every NTM joint at the encoder angles,
        (n_ntm, nb, N) (kept with the inputs)."""
        q_ctrl = inputs.q_ctrl
        spec = self.spec

        def make() -> Float:
            out = np.empty((len(spec.ntm_joints), len(self.ntm_terms), q_ctrl.shape[0]))
            for k, j in enumerate(spec.ntm_joints):
                out[k] = ntm_basis_rows(
                    np.ascontiguousarray(q_ctrl[:, j - 1]),
                    spec.ntm_order,
                    spec.ntm_offset,
                )
            return out

        key = ("ntm", spec.ntm_joints, spec.ntm_order, spec.ntm_offset)
        return inputs.derived(key, make)


def _link_mass_nominal(defn: ModelDefinition) -> Float:
    """The nominal with the general link terms of the robot's ``link_masses``.

    Body k's mass and first moment per unit payload weight (the robot's ``payload_kg``,
    or 1 kg when it has none): ``m_k / m_ref`` and ``m_k c_k / m_ref`` with the centre of
    mass taken from the robot's DH frame k into the model's frame k at the nominal
    geometry (the same frame but for the last row, whose offsets moved into the cam).
    """
    robot = defn.robot
    ch = robot.dh_chain()
    n = robot.n_joints
    # DH frames at the zero configuration, robot base frame.
    T = ch.T_base_0.copy()
    dh_frames = []
    for i in range(n):
        T = T @ dh_transforms(ch.theta_offset[i], ch.d[i], ch.a[i], ch.alpha[i])
        dh_frames.append(T)
    x = defn.nominal.copy()
    rows = defn.rows(x)  # the model's frames at the zero configuration
    fr = chain_frames(
        rows[None, :, OFF],
        rows[:, D],
        rows[:, A],
        rows[:, ALPHA],
        rows[:, BETA] if defn.has_beta else None,
    )
    T_bm = defn.T_robotbase_modelbase
    m_ref = robot.payload_kg or 1.0
    for b in robot.link_masses:
        k = b.frame
        if k not in defn.spec.link_bodies:
            continue
        F = dh_frames[k - 1]
        p_base = F[:3, :3] @ np.asarray(b.com) + F[:3, 3]
        p_model = T_bm[:3, :3].T @ (p_base - T_bm[:3, 3])
        R_k = fr.cols[k][..., 0].T  # columns: the frame's axes
        c = R_k.T @ (p_model - fr.origin[k][:, 0])
        x[defn.layout.index(f"link{k}.m")] = b.mass / m_ref
        for axis, v in zip("xyz", c):
            x[defn.layout.index(f"link{k}.m{axis}")] = b.mass * v / m_ref
    return x
