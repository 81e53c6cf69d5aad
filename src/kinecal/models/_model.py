"""The unified kinematic and joint compliance model (paper Sec. 2.3 and 3).

.. math::
    p_{user} = T_{user,base}\\; \\prod_{i=1}^{n} A_i(\\theta_i)\\; T_{flange,cam}\\; p_{cam},
    \\qquad \\theta = C q_{ctrl} + \\delta\\theta_C + \\delta\\theta_F + \\delta\\theta_{Link}

``T_user_base`` and ``T_flange_cam`` are Euler frames (Eq. 8, 9). Row 1 keeps only ``a1,
alpha1`` and row n only its rotation (Eq. 10): 6 + 2 + 4 (n - 2) + 6 parameters, 30 for six
joints, 27 when the cam rotation is not observable (position-only data). Compliance terms
are in :mod:`kinecal.models._compliance`.

Symbols: ``q_ctrl`` controller angles (N, n) [rad]; ``theta`` kinematic angles; ``p_cam``
the measured point in the cam frame (zero for a reflector at the cam origin).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TypeVar, cast

import numpy as np

from kinecal.errors import DataError, ModelError
from kinecal.geometry import (
    euler_zyx_to_matrix,
    make_transform,
    matrix_to_euler_zyx,
    rot_x,
    rot_z,
    transform_to_euler,
)
from kinecal.models import _kernel
from kinecal.models._chain import (
    ChainFrames,
    chain_frames,
    rotate,
    shifted_trig_if_small,
    vcross,
)
from kinecal.models._compliance import (
    general_link_names,
    general_link_pattern,
    general_link_torque_basis,
    link_torque_basis,
    link_torque_pattern,
    load_torques,
    ntm_basis_rows,
    ntm_names,
    torque_adjoint,
)
from kinecal.models._layout import ParameterLayout, ParamSpec
from kinecal.models._spec import ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import ArrayLike, Float

__all__ = ["CalibrationModel", "ForwardState", "ModelInputs", "ModelOutput"]

_T = TypeVar("_T")
_FRAME = ("x", "y", "z", "r", "w", "p")
# Columns of the per-row value table.
_OFF, _D, _A, _ALPHA, _BETA = range(5)
_ROW_NAMES = ("theta_offset", "d", "a", "alpha", "beta")
_ROW_KINDS = ("angle", "length", "length", "angle", "angle")


def _label(group: str, label: str) -> str:
    return group if label == "" else f"{group}@{label}"


@dataclass(frozen=True)
class ModelInputs:
    """Per-sample inputs of the model (all SI).

    Attributes
    ----------
    q_ctrl : (N, n) controller joint values [rad, m].
    set_index : (N,) int, index into ``spec.sets`` (user frame per session).
    marker_index : (N,) int, index into ``spec.markers`` (cam frame per marker).
    p_cam : (N, 3) point in the cam frame [m] (zeros for a reflector at the cam origin).
    load_scale : (N,) payload of the row relative to the reference payload (1 by default).

    Quantities that depend on the poses alone (the coupled joint angles with their
    cosines and sines, the Fourier bases) are computed once per object and kept
    (:meth:`derived`), as every solver iteration evaluates the same poses. So that they
    cannot go stale, :meth:`make` and :meth:`subset` hold ``q_ctrl`` in a read-only copy;
    make new inputs for other joint values.
    """

    q_ctrl: Float
    set_index: np.ndarray
    marker_index: np.ndarray
    p_cam: Float
    load_scale: Float
    _derived: dict[tuple[object, ...], object] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )

    @classmethod
    def make(
        cls,
        q_ctrl: ArrayLike,
        *,
        set_index: ArrayLike | None = None,
        marker_index: ArrayLike | None = None,
        p_cam: ArrayLike | None = None,
        load_scale: ArrayLike | None = None,
    ) -> ModelInputs:
        q = np.array(q_ctrl, dtype=np.float64, ndmin=2)  # its own copy, read-only below
        N = q.shape[0]
        si = (
            np.zeros(N, np.intp)
            if set_index is None
            else np.asarray(set_index, np.intp)
        )
        mi = (
            np.zeros(N, np.intp)
            if marker_index is None
            else np.asarray(marker_index, np.intp)
        )
        pc = (
            np.zeros((N, 3))
            if p_cam is None
            else np.asarray(p_cam, np.float64).reshape(N, 3)
        )
        ls = (
            np.ones(N)
            if load_scale is None
            else np.asarray(load_scale, np.float64).reshape(N)
        )
        if si.shape != (N,) or mi.shape != (N,):
            raise DataError("set_index and marker_index must have one entry per pose.")
        q.flags.writeable = False
        return cls(q, si, mi, pc, ls)

    @property
    def n(self) -> int:
        return int(self.q_ctrl.shape[0])

    def derived(self, key: tuple[object, ...], make: Callable[[], _T]) -> _T:
        """``make()``, computed on the first call with this ``key`` and kept; its arrays
        (an array or a tuple of them) are made read-only, as every caller shares them."""
        try:
            return cast(_T, self._derived[key])
        except KeyError:
            value = self._derived[key] = make()
            for a in value if isinstance(value, tuple) else (value,):
                if isinstance(a, np.ndarray):
                    a.flags.writeable = False
            return value

    def subset(self, rows: np.ndarray) -> ModelInputs:
        """The inputs of the selected rows (index or boolean mask)."""
        q = self.q_ctrl[rows]
        q.flags.writeable = False
        return ModelInputs(
            q,
            self.set_index[rows],
            self.marker_index[rows],
            self.p_cam[rows],
            self.load_scale[rows],
        )


@dataclass(frozen=True)
class ModelOutput:
    """Model prediction for N poses.

    Attributes
    ----------
    p_user : (N, 3) predicted point in the user frame [m].
    R_user_cam : (N, 3, 3) or None, predicted cam orientation (if asked).
    J_p : (N, 3, P) or None, ``d p_user / d params``.
    J_w : (N, 3, P) or None, rotation Jacobian: ``dR = [J_w dparams] R`` (user frame).
    theta : (N, n) kinematic joint angles actually used (with all error terms) [rad].
    forward : ForwardState or None, the evaluation's intermediate state (with ``keep``),
        for a later Jacobian at the same point (``evaluate(..., reuse=)``).
    """

    p_user: Float
    R_user_cam: Float | None
    J_p: Float | None
    J_w: Float | None
    theta: Float
    forward: ForwardState | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True)
class ForwardState:
    """What a Jacobian needs of a forward evaluation (opaque; see
    :meth:`CalibrationModel.evaluate`). It holds both chains, about 110 numbers a pose."""

    model: CalibrationModel
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
        model: CalibrationModel,
        params: Float,
        inputs: ModelInputs,
        orientation: bool,
    ) -> bool:
        """Whether this state is that of ``model`` at ``params`` and ``inputs``."""
        return (
            self.model is model
            and self.inputs is inputs
            and (self.R_uc is not None or not orientation)
            and np.array_equal(self.params, params)
        )


class CalibrationModel:
    """Unified kinematic model plus joint compliance terms for one robot.

    Parameters
    ----------
    robot : RobotDescription
    spec : ModelSpec
        Terms and options (see :meth:`ModelSpec.preset`).

    Attributes
    ----------
    layout : ParameterLayout
    nominal : ndarray, shape (P,)
        Parameters reproducing the robot's nominal kinematics with the user frame equal to
        the robot base frame and compliance terms zero.
    """

    def __init__(self, robot: RobotDescription, spec: ModelSpec) -> None:
        self.robot = robot
        self.spec = spec
        n = robot.n_joints
        self.n_joints = n
        for j in spec.hayati:
            if not 2 <= j <= n - 1:
                raise ModelError(
                    f"Hayati rows are for joints 2..{n - 1}; got joint {j}."
                )
        for j in spec.ntm_joints:
            if not 1 <= j <= n:
                raise ModelError(
                    f"NTM joint {j} does not exist; the robot has joints 1..{n}."
                )
            if robot.joints[j - 1].kind != "revolute":
                raise ModelError(
                    f"NTM joint {j} is prismatic; a Fourier series needs a revolute joint."
                )
        for k in spec.link_bodies:
            if not 1 <= k <= n:
                raise ModelError(f"link body {k} does not exist; bodies are 1..{n}.")
        if spec.link in ("paper", "rfcm") and robot.self_weight is None:
            raise ModelError(
                f"{robot.name} has no self_weight section; link self-weight terms need one."
            )
        chain = robot.dh_chain()
        self._prismatic = chain.prismatic.copy()
        specs: list[ParamSpec] = []
        nominal: list[float] = []

        # ---------------------------------------------------------- frames: user <- base
        # Joint 1's theta offset and d are absorbed by the base frame (Eq. 10).
        off1, d1 = chain.theta_offset[0], chain.d[0]
        T_base_b0 = chain.T_base_0 @ make_transform(rot_z(off1), [0.0, 0.0, d1])
        self.T_robotbase_modelbase = T_base_b0
        base0 = transform_to_euler(T_base_b0)
        for set_label in spec.sets:
            grp = _label("base", set_label)
            for key, v in zip(_FRAME, base0):
                specs.append(
                    ParamSpec(
                        f"{grp}.{key}", "length" if key in "xyz" else "angle", "base"
                    )
                )
                nominal.append(float(v))

        # ---------------------------------------------------------- joint rows
        row_const = np.zeros((n, 5))
        row_idx = -np.ones((n, 5), dtype=np.intp)
        d_shift = np.zeros(n + 1)  # d moved out of Hayati rows into the next row
        for i in range(n):
            j = i + 1
            off, d, a, al = (
                chain.theta_offset[i],
                chain.d[i],
                chain.a[i],
                chain.alpha[i],
            )
            d = d + d_shift[i]
            if j == 1:
                fields = {"a": a, "alpha": al}
            elif j == n:
                fields = {}
            elif j in spec.hayati:
                if abs(np.sin(al)) > 1e-6:
                    raise ModelError(
                        f"joint {j}: a Hayati row needs axis {j} parallel to axis {j + 1} "
                        f"(alpha = 0 or 180 deg); nominal alpha is {np.degrees(al):.3f} deg."
                    )
                d_shift[i + 1] += d * np.cos(
                    al
                )  # Tz(d) slides to the next parallel axis
                fields = {"theta_offset": off, "a": a, "alpha": al, "beta": 0.0}
            else:
                fields = {"theta_offset": off, "d": d, "a": a, "alpha": al}
            for c, key in enumerate(_ROW_NAMES):
                if key in fields:
                    row_idx[i, c] = len(specs)
                    specs.append(ParamSpec(f"joint{j}.{key}", _ROW_KINDS[c], "joint"))
                    nominal.append(float(fields[key]))
        self._row_const = row_const
        self._row_idx = row_idx
        self._row_mask = row_idx >= 0
        self._has_beta = bool(np.any(row_idx[:, _BETA] >= 0))

        # ---------------------------------------------------------- frames: flange <- cam
        # The last row keeps only its rotation; its offset, d, a, alpha, the physical
        # flange and the nominal tool become the starting value of T_flange_cam (Eq. 9).
        T_fc = (
            make_transform(
                rot_z(chain.theta_offset[-1]), [0.0, 0.0, chain.d[-1] + d_shift[n - 1]]
            )
            @ make_transform(rot_x(chain.alpha[-1]), [chain.a[-1], 0.0, 0.0])
            @ chain.T_n_flange
            @ robot.T_flange_tool
        )
        cam0 = transform_to_euler(T_fc)
        self._cam_keys = _FRAME if spec.cam_rotation else _FRAME[:3]
        for marker in spec.markers:
            grp = _label("cam", marker)
            for key in self._cam_keys:
                v = cam0[_FRAME.index(key)]
                specs.append(
                    ParamSpec(
                        f"{grp}.{key}", "length" if key in "xyz" else "angle", "cam"
                    )
                )
                nominal.append(float(v))
        # Reference rotations (fixed): identity for identified rotations; the nominal
        # rotation when the cam rotation is not identified.
        self.R_ref_base = np.broadcast_to(np.eye(3), (len(spec.sets), 3, 3)).copy()
        R_cam_fixed = T_fc[:3, :3] if not spec.cam_rotation else np.eye(3)
        self.R_ref_cam = np.broadcast_to(R_cam_fixed, (len(spec.markers), 3, 3)).copy()

        # ---------------------------------------------------------- compliance
        self._ntm_cols = (
            ntm_names(spec.ntm_order, spec.ntm_offset) if spec.ntm_joints else []
        )
        self._ntm_start = len(specs)
        for j in spec.ntm_joints:
            for coef in self._ntm_cols:
                specs.append(ParamSpec(f"joint{j}.{coef}", "ntm", "ntm"))
                nominal.append(0.0)
        self._load_start = len(specs)
        if spec.load:
            for j in range(1, n + 1):
                specs.append(ParamSpec(f"joint{j}.lambda", "compliance", "load"))
                nominal.append(0.0)
        self._link_start = len(specs)
        self._link_names: list[str] = []
        if spec.link == "paper":
            self._link_names = ["link.s1", "link.s2"]
        elif spec.link == "rfcm":
            self._link_names = ["link.s1", "link.s2_shoulder", "link.s2_elbow"]
        if spec.link_bodies:
            self._link_names = self._link_names + general_link_names(spec.link_bodies)
        for nm in self._link_names:
            specs.append(
                ParamSpec(nm, "ratio" if nm.endswith(".m") else "moment", "link")
            )
            nominal.append(0.0)
        self.layout = ParameterLayout(specs)
        self.nominal = np.array(nominal)

        # Gravity direction in the model base frame (the robot base rotated by joint 1's
        # absorbed offset).
        g_unit = robot.gravity / np.linalg.norm(robot.gravity)
        self.g_hat = T_base_b0[:3, :3].T @ g_unit
        sw = robot.self_weight
        self._sw = sw
        if sw is not None and spec.link in ("paper", "rfcm"):
            a_sh = chain.a[sw.shoulder - 1]
            self._x_sign = 1.0 if a_sh >= 0 else -1.0

        # Index tables.
        self._base_idx = np.array(
            [
                [self.layout.index(f"{_label('base', s)}.{k}") for k in _FRAME]
                for s in spec.sets
            ]
        )
        self._cam_idx = np.array(
            [
                [self.layout.index(f"{_label('cam', m)}.{k}") for k in self._cam_keys]
                for m in spec.markers
            ]
        )
        self._lam_idx = (
            np.arange(self._load_start, self._load_start + n)
            if spec.load
            else np.zeros(0, np.intp)
        )
        # Where a link parameter s_k acts on joint j, the deflection holds the product
        # lambda*_j s_k: (joint index, column of the link basis) of every such pair.
        pattern: list[tuple[int, int]] = []
        if spec.link in ("paper", "rfcm") and sw is not None:
            pattern += link_torque_pattern(spec.link, sw.shoulder, sw.elbow)
        if spec.link_bodies:
            first = len(self._link_names) - 4 * len(spec.link_bodies)
            pattern += [
                (j, first + k)
                for j, k in general_link_pattern(spec.link_bodies, self._prismatic)
            ]
        self._products = [(j - 1, k) for j, k in pattern]
        self._kernel_static = _kernel.tables(self)  # None: the numpy code runs

    # ------------------------------------------------------------------ helpers
    @property
    def size(self) -> int:
        return self.layout.size

    @property
    def base_index(self) -> np.ndarray:
        """Indices of the user-frame parameters ``x, y, z, r, w, p``, shape (sets, 6)."""
        return self._base_idx

    @property
    def cam_index(self) -> np.ndarray:
        """Indices of the cam-frame parameters, shape (markers, 6) or (markers, 3)."""
        return self._cam_idx

    @property
    def link_products(self) -> list[tuple[int, int]]:
        """Pairs ``(index of lambda*_j, index of s_k)`` of every link parameter s_k and
        joint j it loads: the deflection of joint j holds the product ``lambda*_j s_k``
        (Eq. 26). :meth:`evaluate` with ``products=True`` appends the Jacobian columns of
        these products, in this order."""
        return [
            (int(self._lam_idx[j]), self._link_start + k) for j, k in self._products
        ]

    def _rows(self, params: Float) -> Float:
        rows = self._row_const.copy()
        rows[self._row_mask] = params[self._row_idx[self._row_mask]]
        return rows

    def base_frames(self, params: Float) -> tuple[Float, Float]:
        """User frames ``(R_user_base (S, 3, 3), t_user_base (S, 3))`` of every set."""
        v = params[self._base_idx]  # (S, 6)
        R = self.R_ref_base @ euler_zyx_to_matrix(v[:, 3:])
        return R, v[:, :3].copy()

    def cam_frames(self, params: Float) -> tuple[Float, Float]:
        """Cam frames ``(R_flange_cam (M, 3, 3), t_flange_cam (M, 3))`` of every marker."""
        v = params[self._cam_idx]
        if self.spec.cam_rotation:
            R = self.R_ref_cam @ euler_zyx_to_matrix(v[:, 3:])
        else:
            R = self.R_ref_cam.copy()
        return R, v[:, :3].copy()

    def frame_euler(self, params: Float, which: str) -> Float:
        """Total Euler values ``[x, y, z, r, w, p]`` (K, 6) of 'base' or 'cam' frames.

        Differs from the raw parameters only where a reference rotation is set.
        """
        R, t = self.base_frames(params) if which == "base" else self.cam_frames(params)
        return np.concatenate([t, matrix_to_euler_zyx(R)], axis=1)

    def _coupled(self, inputs: ModelInputs) -> tuple[Float, Float, Float]:
        """Kinematic angles ``C q_ctrl`` (n, N) of the inputs, with their cosines and
        sines (computed once per inputs object)."""
        C = self.robot.coupling

        def make() -> tuple[Float, Float, Float]:
            th = C @ inputs.q_ctrl.T
            return th, np.cos(th), np.sin(th)

        return inputs.derived(("coupled", C.tobytes()), make)

    def _ntm(self, params: Float, inputs: ModelInputs) -> tuple[Float, list[Float]]:
        """NTM joint-angle errors (n, N) and the basis (nb, N) per NTM joint (the bases are
        computed once per inputs object)."""
        N = inputs.q_ctrl.shape[0]
        dth = np.zeros((self.n_joints, N))
        stack = self._ntm_bases(inputs)
        nb = len(self._ntm_cols)
        for k, j in enumerate(self.spec.ntm_joints):
            coef = params[self._ntm_start + k * nb : self._ntm_start + (k + 1) * nb]
            dth[j - 1] += coef @ stack[k]  # Eq. (17)
        return dth, list(stack)

    def _ntm_bases(self, inputs: ModelInputs) -> Float:
        """The Fourier bases of every NTM joint, (n_ntm, nb, N) (kept with the inputs)."""
        q_ctrl = inputs.q_ctrl
        spec = self.spec

        def make() -> Float:
            out = np.empty((len(spec.ntm_joints), len(self._ntm_cols), q_ctrl.shape[0]))
            for k, j in enumerate(spec.ntm_joints):
                out[k] = ntm_basis_rows(
                    np.ascontiguousarray(q_ctrl[:, j - 1]),
                    spec.ntm_order,
                    spec.ntm_offset,
                )
            return out

        key = ("ntm", spec.ntm_joints, spec.ntm_order, spec.ntm_offset)
        return inputs.derived(key, make)

    def _row_trig(
        self, rows: Float, coupled: tuple[Float, Float, Float], dth: Float | None
    ) -> tuple[Float, Float] | None:
        """Cosines and sines (n, N) of the row angles ``C q + offset + dth`` from those of
        ``C q``: the offsets by the angle sums, the small NTM errors ``dth`` by the
        series of ``shifted_trig``. None for arms with prismatic joints or large errors.
        """
        if self._prismatic.any():
            return None
        _, cq, sq = coupled
        off = rows[:, _OFF, None]
        co, so = np.cos(off), np.sin(off)
        ct = cq * co
        ct -= sq * so
        st = sq * co
        st += cq * so
        if dth is not None:
            js = [j - 1 for j in self.spec.ntm_joints]
            J: list[int] | slice = js
            if js == list(range(js[0], js[-1] + 1)):  # views, no gather
                J = slice(js[0], js[-1] + 1)
            shifted = shifted_trig_if_small(ct[J], st[J], dth[J])
            if shifted is None:
                return None
            ct[J], st[J] = shifted
        return ct, st

    def _link_basis(self, frames: ChainFrames, g: Float | None = None) -> Float:
        """Link-weight torque per unit of each link parameter, (n, n_link, N), for gravity
        ``g`` in the frame of ``frames`` (default: the model base frame's)."""
        g = self.g_hat if g is None else g
        parts = []
        if self.spec.link in ("paper", "rfcm"):
            sw = self._sw
            if sw is None:  # pragma: no cover - rejected in __init__
                raise ModelError("no self_weight section")
            parts.append(
                link_torque_basis(
                    frames,
                    g,
                    sw.shoulder,
                    sw.elbow,
                    sw.wrist_frame,
                    self._x_sign,
                    self.spec.link,
                )
            )
        if self.spec.link_bodies:
            parts.append(
                general_link_torque_basis(
                    frames, g, self.spec.link_bodies, self._prismatic
                )
            )
        return parts[0] if len(parts) == 1 else np.concatenate(parts, axis=1)

    def _frames(
        self,
        theta: Float,
        rows: Float,
        base: tuple[Float, Float] | None = None,
        trig: tuple[Float, Float] | None = None,
    ) -> ChainFrames:
        """Chain frames for kinematic joint values ``theta`` (n, N), in the model base
        frame or in the frame ``base`` places it in (see :func:`chain_frames`). ``trig``
        gives the cosines and sines of the row angles when the caller has them."""
        pr = self._prismatic
        if np.any(pr):
            th = rows[:, _OFF, None] + np.where(pr[:, None], 0.0, theta)
            d = (rows[:, _D, None] + np.where(pr[:, None], theta, 0.0)).T
        else:
            th = rows[:, _OFF, None] + theta
            d = rows[:, _D]
        beta = rows[:, _BETA] if self._has_beta else None
        return chain_frames(th.T, d, rows[:, _A], rows[:, _ALPHA], beta, base, trig)

    def _user_base(
        self, R_b: Float, t_b: Float, set_index: np.ndarray
    ) -> tuple[tuple[Float, Float], Float]:
        """Where the chain starts in the user frame (for :meth:`_frames`) and gravity
        there: one frame and (3,) for a single set, per pose and (3, N) for several."""
        if len(self.spec.sets) == 1:
            return (R_b[0], t_b[0]), R_b[0] @ self.g_hat
        R = R_b[set_index]
        return (R, t_b[set_index]), (R @ self.g_hat).T

    def _flange_point(
        self, R_c: Float, t_c: Float, inputs: ModelInputs
    ) -> tuple[Float, Float]:
        """The measured point in the flange frame, and its offset from the cam origin
        (both (3, N)): ``t_fc + R_fc p_cam`` and ``R_fc p_cam``."""
        if len(self.spec.markers) == 1:
            p_rot = R_c[0] @ inputs.p_cam.T
            return t_c[0][:, None] + p_rot, p_rot
        mi = inputs.marker_index
        p_rot = np.einsum("nij,nj->in", R_c[mi], inputs.p_cam)
        return t_c[mi].T + p_rot, p_rot

    def _joint_columns(self, Z: Float, rot_cols: Float, orientation: bool) -> Float:
        """``d output / d theta_i`` (n, 3 or 6, N) from the joint axes ``Z`` and the
        point's velocity ``z × (p - o)`` of a unit rotation about each (n, 3, N)
        (``rot_cols`` itself for revolute joints and the position only)."""
        if not orientation and not self._prismatic.any():
            return rot_cols
        pr = self._prismatic[:, None, None]
        G = np.zeros((Z.shape[0], 6 if orientation else 3, Z.shape[-1]))
        G[:, :3] = np.where(pr, Z, rot_cols)
        if orientation:
            G[:, 3:] = np.where(pr, 0.0, Z)
        return G

    # ------------------------------------------------------------------ evaluation
    def evaluate(
        self,
        params: ArrayLike,
        inputs: ModelInputs,
        *,
        orientation: bool = False,
        jacobian: bool = False,
        products: bool = False,
        keep: bool = False,
        reuse: ForwardState | None = None,
    ) -> ModelOutput:
        """Predict the measured point (and cam orientation) for every pose.

        Parameters
        ----------
        params : array_like, shape (P,)
            Flat parameter vector of :attr:`layout` (SI).
        inputs : ModelInputs
        orientation : bool
            Also return ``R_user_cam`` (and its Jacobian).
        jacobian : bool
            Also return exact analytic Jacobians with respect to every parameter, including
            the dependence of the compliance torques on the arm's geometry.
        products : bool
            With ``jacobian``, append one column per pair of :attr:`link_products`: the
            derivative with respect to the product ``lambda*_j s_k`` of the deflection of
            joint j, all parameters held (``P + len(link_products)`` columns in all).
        keep : bool
            Attach the intermediate state (``ModelOutput.forward``, both chains: about
            110 numbers a pose) for a later Jacobian at the same point. Only the numpy
            code keeps one: the compiled kernel (:mod:`kinecal.models._kernel`) computes
            the forward kinematics again at a small part of a Jacobian's cost, and its
            outputs have ``forward`` None.
        reuse : ForwardState, optional
            The ``forward`` of an earlier output: when it is this model's at the same
            parameters and the same ``inputs`` object (its arrays unchanged since), its
            forward kinematics are not computed again (otherwise it is ignored). The
            result is the same.

        Returns
        -------
        ModelOutput
            The Jacobians are views of one parameter-major array of shape (P', c, N):
            ``J_p.transpose(2, 1, 0)`` gives it back without a copy, every column of every
            component a contiguous row (what :func:`kinecal.identification.normal_equations`
            multiplies).
        """
        p = np.asarray(params, dtype=np.float64)
        if p.shape != (self.size,):
            raise ModelError(f"params must have shape ({self.size},); got {p.shape}.")
        q = inputs.q_ctrl
        if q.ndim != 2 or q.shape[1] != self.n_joints:
            raise DataError(
                f"q_ctrl must have shape (N, {self.n_joints}) for {self.robot.name}; got {q.shape}."
            )
        static = _kernel.active_tables(self)
        if static is not None:  # the compiled kernel (see kinecal.models._kernel)
            p_user, R_uc_c, J, theta_c = _kernel.evaluate(
                static,
                self,
                p,
                inputs,
                orientation=orientation,
                jacobian=jacobian,
                products=products,
                alloc=_alloc,
            )
            return ModelOutput(
                p_user,
                R_uc_c,
                None if J is None else J[:, :3].transpose(2, 1, 0),
                J[:, 3:].transpose(2, 1, 0) if J is not None and orientation else None,
                theta_c.T,
            )
        if reuse is not None and reuse.serves(self, p, inputs, orientation):
            fw = reuse
        else:
            fw = self._forward(p, inputs, orientation)
        R_uc = fw.R_uc if orientation else None
        out = ModelOutput(fw.p_user, R_uc, None, None, fw.theta, fw if keep else None)
        if not jacobian:
            return out
        spec = self.spec
        N, n = q.shape
        ntm_bases, fr0, fr, p_load, tau, link_T, g = (
            fw.ntm_bases,
            fw.fr0,
            fw.fr,
            fw.p_load,
            fw.tau,
            fw.link_T,
            fw.g,
        )
        t_b, p_u, p_cam_fl = fw.t_base, fw.p_u, fw.p_cam_fl
        R_fl = fr.cols[n]
        single_s, single_m = len(spec.sets) == 1, len(spec.markers) == 1
        si, mi = inputs.set_index, inputs.marker_index

        # Columns (user frame), position rows 0:3 and rotation rows 3:6, stored
        # parameter-major: every column of every component is a contiguous row.
        P = self.size
        c = 6 if orientation else 3
        K = len(self._products) if products else 0
        # Every row is assigned below; only the parts no term writes are zeroed.
        Jb = _alloc((P + K, c, N))
        Z = fr.cols[:n, 2]  # (n, 3, N): joint i + 1 turns about z_i
        rot_cols = vcross(Z, p_u - fr.origin[:n])  # rotation about z_i
        G = self._joint_columns(Z, rot_cols, orientation)  # d output / d theta_i
        ax = fr.a_dir
        alpha_cols = vcross(ax, p_u - fr.origin[1:])
        for i in range(n):
            idx = self._row_idx[i]
            if idx[_OFF] >= 0:
                Jb[idx[_OFF], :3] = rot_cols[i]
                if orientation:
                    Jb[idx[_OFF], 3:] = Z[i]
            if idx[_D] >= 0:
                Jb[idx[_D], :3] = Z[i]
                Jb[idx[_D], 3:] = 0.0
            if idx[_A] >= 0:
                Jb[idx[_A], :3] = ax[i]
                Jb[idx[_A], 3:] = 0.0
            if idx[_ALPHA] >= 0:
                Jb[idx[_ALPHA], :3] = alpha_cols[i]
                if orientation:
                    Jb[idx[_ALPHA], 3:] = ax[i]
            if idx[_BETA] >= 0:
                y_i = fr.cols[i + 1, 1]
                Jb[idx[_BETA], :3] = vcross(y_i, p_u - fr.origin[i + 1])
                if orientation:
                    Jb[idx[_BETA], 3:] = y_i

        # Cam frame parameters (Eq. 9), per marker.
        rel_cam = rotate(R_fl, p_cam_fl)
        cam_v = p[self._cam_idx]
        for m in range(len(spec.markers)):
            mask = 1.0 if single_m else (mi == m).astype(np.float64)
            cols = self._cam_idx[m]
            for k in range(3):
                Jb[cols[k], :3] = R_fl[k] * mask
                Jb[cols[k], 3:] = 0.0
            if spec.cam_rotation:
                axes = _euler_axes(self.R_ref_cam[m], cam_v[m, 3:])  # columns r, w, p
                ax_b = np.einsum("cin,ck->kin", R_fl, axes)  # (3, 3, N)
                Jb[cols[3:], :3] = vcross(ax_b, rel_cam) * mask
                if orientation:
                    Jb[cols[3:], 3:] = ax_b * mask

        # Parameters acting through the joint angles.
        turns: dict[int, Float] = {}
        if spec.load:
            assert fr0 is not None and p_load is not None and tau is not None
            H = G * p[self._lam_idx, None, None]  # lambda* d output / d theta
            turns = self._add_torque_geometry(p, inputs, fr0, p_load, g, H, Jb)
            Jb[self._lam_idx] = G * tau[:, None, :]
            if link_T is not None:
                # d output / d s_k = sum_j H_j link_T[j, k] over the pattern's joints
                Jb[self._link_start : self._link_start + len(self._link_names)] = 0.0
                for j, k in self._products:
                    Jb[self._link_start + k] += H[j] * link_T[j, k]
                if products:
                    for i, (j, k) in enumerate(self._products):
                        Jb[P + i] = G[j] * link_T[j, k]
        # An NTM term turns its joint: through the chain (G) and through the torques.
        nb = len(self._ntm_cols)
        for k, j in enumerate(spec.ntm_joints):
            sl = slice(self._ntm_start + k * nb, self._ntm_start + (k + 1) * nb)
            d_turn = G[j - 1] + turns[j] if j in turns else G[j - 1]
            Jb[sl] = d_turn * ntm_bases[k][:, None, :]

        # User frame parameters (Eq. 8), per set.
        base_v = p[self._base_idx]
        for k_set in range(len(spec.sets)):
            mask = np.ones(N) if single_s else (si == k_set).astype(np.float64)
            cols = self._base_idx[k_set]
            Jb[cols[:3]] = 0.0
            for k in range(3):
                Jb[cols[k], k] = mask
            axes = _euler_axes(self.R_ref_base[k_set], base_v[k_set, 3:])
            rel = (p_u - t_b[k_set][:, None]) * mask
            Jb[cols[3:], :3] = vcross(axes.T[:, :, None], rel)
            if orientation:
                Jb[cols[3:], 3:] = axes.T[:, :, None] * mask
        return ModelOutput(
            fw.p_user,
            R_uc,
            Jb[:, :3].transpose(2, 1, 0),
            Jb[:, 3:].transpose(2, 1, 0) if orientation else None,
            fw.theta,
            out.forward,
        )

    def _forward(
        self, p: Float, inputs: ModelInputs, orientation: bool
    ) -> ForwardState:
        """The forward evaluation of :meth:`evaluate` (checked inputs), with the state its
        Jacobian needs."""
        q = inputs.q_ctrl
        # Everything below keeps the pose axis last: vectors are (3, N), see _chain.
        # Both chains start at the user frame, so every point, axis and Jacobian column
        # is in the user frame from the start; the torques are frame-invariant with
        # gravity mapped along.
        spec = self.spec
        n = q.shape[1]
        rows = self._rows(p)
        coupled = self._coupled(inputs)
        theta = coupled[0]  # (n, N), kept with the inputs: not modified in place
        ntm_bases: list[Float] = []
        dth_c = None
        if spec.ntm_joints:
            dth_c, ntm_bases = self._ntm(p, inputs)
            theta = theta + dth_c
        trig = self._row_trig(rows, coupled, dth_c)

        R_c, t_c = self.cam_frames(p)
        R_b, t_b = self.base_frames(p)
        base, g = self._user_base(R_b, t_b, inputs.set_index)
        tau = link_T = fr0 = p_load = None
        if spec.load:
            fr0 = self._frames(theta, rows, base, trig)
            # Load point: origin of the first marker's cam frame (Eq. 19 with Delta = 0).
            p_load = fr0.origin[n] + rotate(fr0.cols[n], t_c[0])
            tau = load_torques(fr0, p_load, g, self._prismatic)
            tau *= inputs.load_scale
            if self._link_names:
                link_T = self._link_basis(fr0, g)
                s = p[self._link_start : self._link_start + len(self._link_names)]
                tau += np.einsum("jsn,s->jn", link_T, s)  # Eq. (25)
            deflection = p[self._lam_idx, None] * tau  # Eq. (22), (24), (26)
            th = theta + deflection
            if self._prismatic.any():  # a prismatic row's angle does not change
                deflection = np.where(self._prismatic[:, None], 0.0, deflection)
            shifted = shifted_trig_if_small(fr0.cos, fr0.sin, deflection)
            fr = self._frames(th, rows, base, shifted)
        else:
            th = theta if dth_c is not None else theta.copy()  # not the kept array
            fr = self._frames(th, rows, base, trig)

        p_fl, p_cam_fl = self._flange_point(R_c, t_c, inputs)
        p_u = fr.origin[n] + rotate(fr.cols[n], p_fl)
        R_uc = None
        if orientation:
            mi = inputs.marker_index
            R_uc = fr.R[:, n] @ (R_c[0] if len(spec.markers) == 1 else R_c[mi])
        return ForwardState(
            model=self,
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

    def _add_torque_geometry(
        self,
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
        torque derivatives. This makes the Jacobian exact (checked against finite
        differences).

        Returns the term of a unit turn of each NTM joint (joint -> (c, N)): the caller
        scales it by the joint's Fourier basis with the chain's own column.
        """
        n = self.n_joints
        link = None
        if self.spec.link in ("paper", "rfcm"):
            sw = self._sw
            assert sw is not None
            n_lump = 2 if self.spec.link == "paper" else 3
            s_vals = p[self._link_start : self._link_start + n_lump]
            link = (
                self.spec.link,
                (sw.shoulder, sw.elbow, sw.wrist_frame),
                self._x_sign,
                s_vals,
            )
        bodies = None
        if self.spec.link_bodies:
            end = self._link_start + len(self._link_names)
            start = end - 4 * len(self.spec.link_bodies)
            bodies = (self.spec.link_bodies, p[start:end])
        adjoint = torque_adjoint(
            fr0, p_load, g, self._prismatic, H, inputs.load_scale, link, bodies
        )
        ntm = set(self.spec.ntm_joints)
        turns: dict[int, Float] = {}
        for f, M, V in adjoint.sweep():
            if f == n + 1:  # the load point moves with the first marker's translation
                Jb[self._cam_idx[0][:3]] += _apply(V, fr0.cols[n])
                continue
            # Row i = f - 1 moves the frames f.. by the twist of each of its parameters.
            i = f - 1
            idx = self._row_idx[i]
            z, o = fr0.cols[i, 2], fr0.origin[i]
            ax, o1 = fr0.a_dir[i], fr0.origin[i + 1]
            if idx[_OFF] >= 0 or f in ntm:  # joint f turning about z_i through o_i
                d_turn = _apply(M, z) + _apply(V, vcross(o, z))
                if idx[_OFF] >= 0:
                    Jb[idx[_OFF]] += d_turn
                if f in ntm:
                    turns[f] = d_turn
            if idx[_D] >= 0:
                Jb[idx[_D]] += _apply(V, z)
            if idx[_A] >= 0:
                Jb[idx[_A]] += _apply(V, ax)
            if idx[_ALPHA] >= 0:
                Jb[idx[_ALPHA]] += _apply(M, ax) + _apply(V, vcross(o1, ax))
            if idx[_BETA] >= 0:
                y = fr0.cols[i + 1, 1]
                Jb[idx[_BETA]] += _apply(M, y) + _apply(V, vcross(o1, y))
        return turns

    def flange_frames(
        self, params: ArrayLike, inputs: ModelInputs
    ) -> tuple[Float, Float]:
        """Model flange frames in the model base, ``(R (N, 3, 3), o (N, 3))``.

        Includes every joint-angle error term; the user and cam frames are not applied.
        """
        p = np.asarray(params, dtype=np.float64)
        out = self.evaluate(p, inputs)
        fr = self._frames(out.theta.T, self._rows(p))
        return np.ascontiguousarray(fr.R[:, -1]), np.ascontiguousarray(fr.o[:, -1])

    def with_references(
        self, R_ref_base: Float | None = None, R_ref_cam: Float | None = None
    ) -> CalibrationModel:
        """A copy with other fixed reference rotations for the user / cam frames.

        A frame is ``Trans(x, y, z) · R_ref · Rz(r) Ry(w) Rx(p)``; a reference rotation
        keeps the Euler angles away from gimbal lock (``|w|`` near 90 deg). The default is
        the identity (the paper's Eq. 8-9 exactly).
        """
        m = copy.copy(self)
        if R_ref_base is not None:
            m.R_ref_base = np.array(R_ref_base, dtype=np.float64).reshape(
                self.R_ref_base.shape
            )
        if R_ref_cam is not None:
            if not self.spec.cam_rotation:
                raise ModelError(
                    "the cam rotation is fixed in this model (cam_rotation=False)."
                )
            m.R_ref_cam = np.array(R_ref_cam, dtype=np.float64).reshape(
                self.R_ref_cam.shape
            )
        return m

    def joint_jacobian(self, params: ArrayLike, inputs: ModelInputs) -> Float:
        """Geometric Jacobian of the model point w.r.t. the kinematic joint angles.

        The model point is ``T_user_cam p_cam`` (the cam origin when ``p_cam`` is zero).

        Returns
        -------
        ndarray, shape (N, 6, n)
            Rows ``[v; omega]`` (translation first) in the user frame: ``d p_user/d theta``
            and the angular velocity per unit joint rate, at the model's deflected angles.
            Multiply by ``robot.coupling`` for the derivative w.r.t. ``q_ctrl``.
        """
        p = np.asarray(params, dtype=np.float64)
        out = self.evaluate(p, inputs)
        base, _ = self._user_base(*self.base_frames(p), inputs.set_index)
        fr = self._frames(out.theta.T, self._rows(p), base)  # in the user frame
        n = self.n_joints
        R_c, t_c = self.cam_frames(p)
        p_fl, _ = self._flange_point(R_c, t_c, inputs)
        p_u = fr.origin[n] + rotate(fr.cols[n], p_fl)
        Z = fr.cols[:n, 2]
        G = self._joint_columns(Z, vcross(Z, p_u - fr.origin[:n]), True)
        return np.ascontiguousarray(G.transpose(2, 1, 0))  # (N, 6, n)

    def with_spec(self, spec: ModelSpec) -> CalibrationModel:
        """A model of the same robot with other terms (reference rotations are kept)."""
        m = CalibrationModel(self.robot, spec)
        if spec.sets == self.spec.sets:
            m.R_ref_base = self.R_ref_base.copy()
        if (
            spec.markers == self.spec.markers
            and spec.cam_rotation == self.spec.cam_rotation
        ):
            m.R_ref_cam = self.R_ref_cam.copy()
        return m


def _alloc(shape: tuple[int, ...]) -> Float:
    """Uninitialised storage of the Jacobian (a test fills it with NaN instead, to show
    that :meth:`CalibrationModel.evaluate` writes every entry)."""
    return np.empty(shape)


def _apply(M: Float, w: Float) -> Float:
    """``M w`` per pose for M (c, 3, N): w (3, N) gives (c, N), w (k, 3, N) gives (k, c, N)."""
    if w.ndim == 2:
        return np.einsum("cbn,bn->cn", M, w)
    return np.einsum("cbn,kbn->kcn", M, w)


def _euler_axes(R_ref: Float, rwp: Float) -> Float:
    """Rotation axes (columns r, w, p) of ``R_ref Rz(r) Ry(w) Rx(p)`` in the parent frame."""
    r, w = rwp[0], rwp[1]
    Rz = euler_zyx_to_matrix(np.array([r, 0.0, 0.0]))
    Rzy = euler_zyx_to_matrix(np.array([r, w, 0.0]))
    return np.stack([R_ref[:, 2], (R_ref @ Rz)[:, 1], (R_ref @ Rzy)[:, 0]], axis=1)
