"""The unified kinematic and joint compliance model (paper Sec. 2.3 and 3).

.. math::
    p_{user} = T_{user,base}\\; \\prod_{i=1}^{n} A_i(\\theta_i)\\; T_{flange,cam}\\; p_{cam},
    \\qquad \\theta = C q_{ctrl} + \\delta\\theta_C + \\delta\\theta_F + \\delta\\theta_{Link}

:class:`CalibrationModel` holds the model's definition (:class:`ModelDefinition`: the
parameter layout, nominal values and index tables, :mod:`kinecal.models._definition`) and
hands each evaluation to one of two codes that compute the same numbers: the compiled
kernel (:mod:`kinecal.models._kernel`) where it is built and applies, else the numpy code
(:mod:`kinecal.models._numpy_forward`, :mod:`kinecal.models._numpy_jacobian`).

Symbols: ``q_ctrl`` controller angles (N, n) [rad]; ``theta`` kinematic angles; ``p_cam``
the measured point in the cam frame (zero for a reflector at the cam origin).
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from kinecal._record import Record
from kinecal.errors import DataError, ModelError
from kinecal.models import _kernel
from kinecal.models._definition import ModelDefinition
from kinecal.models._inputs import ModelInputs
from kinecal.models._layout import ParameterLayout
from kinecal.models._spec import ModelSpec
from kinecal.robot import RobotDescription
from kinecal.typing import ArrayLike, Float

if TYPE_CHECKING:  # the numpy code loads where the compiled kernel does not apply
    from kinecal.models._numpy_forward import ForwardState

__all__ = [
    "CalibrationModel",
    "ModelInputs",
    "ModelOutput",
    "kernel_name",
    "pass_counts",
]

# Evaluations of every model in this process (worker processes count their own): "forward"
# without a Jacobian, "jacobian" with one, and "jacobian_entries" the poses x columns of
# those Jacobians (their work, as models and row subsets differ in size). For benchmarks
# and tests of how many passes over the data a calibration takes (issue 36).
_PASSES = {"forward": 0, "jacobian": 0, "jacobian_entries": 0}


def pass_counts() -> dict[str, int]:
    """How many model evaluations this process has run so far (see ``_PASSES``); the
    difference of two calls counts the passes of what ran between them."""
    return dict(_PASSES)


@dataclass(frozen=True, eq=False, repr=False)
class ModelOutput(Record):
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


class CalibrationModel:
    """Unified kinematic model plus joint compliance terms for one robot.

    Parameters
    ----------
    robot : RobotDescription
    spec : ModelSpec
        Terms and options (see :meth:`ModelSpec.preset`).

    Attributes
    ----------
    definition : ModelDefinition
        The parameters and the tables that place them (what the evaluators read).
    layout : ParameterLayout
    nominal : ndarray, shape (P,)
        Parameters reproducing the robot's nominal kinematics with the user frame equal to
        the robot base frame and compliance terms zero.
    """

    def __init__(self, robot: RobotDescription, spec: ModelSpec) -> None:
        self._set_definition(ModelDefinition.build(robot, spec))

    @classmethod
    def from_definition(cls, definition: ModelDefinition) -> CalibrationModel:
        """The model of a definition (built by :meth:`ModelDefinition.build`)."""
        model = cls.__new__(cls)
        model._set_definition(definition)
        return model

    def _set_definition(self, definition: ModelDefinition) -> None:
        self.definition = definition
        # The compiled kernel's tables (None: the numpy code runs), once per model.
        self._kernel_tables = _kernel.tables(definition)

    # ------------------------------------------------------------------ the definition
    @property
    def robot(self) -> RobotDescription:
        return self.definition.robot

    @property
    def spec(self) -> ModelSpec:
        return self.definition.spec

    @property
    def n_joints(self) -> int:
        return self.definition.n_joints

    @property
    def layout(self) -> ParameterLayout:
        return self.definition.layout

    @property
    def nominal(self) -> Float:
        """Nominal parameters (P,) (read-only)."""
        return self.definition.nominal

    @property
    def size(self) -> int:
        return self.definition.size

    @property
    def T_robotbase_modelbase(self) -> Float:
        """The model base frame in the robot description's base frame, (4, 4) [m]."""
        return self.definition.T_robotbase_modelbase

    @property
    def g_hat(self) -> Float:
        """Unit gravity direction (3,) in the model base frame."""
        return self.definition.g_hat

    @property
    def R_ref_base(self) -> Float:
        """Reference rotations (S, 3, 3) of the user frames (:meth:`with_references`)."""
        return self.definition.R_ref_base

    @property
    def R_ref_cam(self) -> Float:
        """Reference rotations (M, 3, 3) of the cam frames (:meth:`with_references`)."""
        return self.definition.R_ref_cam

    @property
    def base_index(self) -> np.ndarray:
        """Indices of the user-frame parameters ``x, y, z, r, w, p``, shape (sets, 6)."""
        return self.definition.base_idx

    @property
    def cam_index(self) -> np.ndarray:
        """Indices of the cam-frame parameters, shape (markers, 6) or (markers, 3)."""
        return self.definition.cam_idx

    @property
    def link_products(self) -> list[tuple[int, int]]:
        """Pairs ``(index of lambda*_j, index of s_k)`` of every link parameter s_k and
        joint j it loads: the deflection of joint j holds the product ``lambda*_j s_k``
        (Eq. 26). :meth:`evaluate` with ``products=True`` appends the Jacobian columns of
        these products, in this order."""
        return self.definition.link_products

    def base_frames(self, params: Float) -> tuple[Float, Float]:
        """User frames ``(R_user_base (S, 3, 3), t_user_base (S, 3))`` of every set."""
        return self.definition.base_frames(params)

    def cam_frames(self, params: Float) -> tuple[Float, Float]:
        """Cam frames ``(R_flange_cam (M, 3, 3), t_flange_cam (M, 3))`` of every marker."""
        return self.definition.cam_frames(params)

    def frame_euler(self, params: Float, which: str) -> Float:
        """Total Euler values ``[x, y, z, r, w, p]`` (K, 6) of 'base' or 'cam' frames.

        Differs from the raw parameters only where a reference rotation is set.
        """
        return self.definition.frame_euler(params, which)

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
        defn = self.definition
        if jacobian:
            _PASSES["jacobian"] += 1
            cols = self.size + (len(self.link_products) if products else 0)
            _PASSES["jacobian_entries"] += q.shape[0] * cols
        else:
            _PASSES["forward"] += 1
        static = _kernel.active_tables(defn, self._kernel_tables)
        if static is not None:  # the compiled kernel (see kinecal.models._kernel)
            p_user, R_uc_c, J, theta_c = _kernel.evaluate(
                static,
                defn,
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
        if reuse is not None and reuse.serves(defn, p, inputs, orientation):
            fw = reuse
        else:
            fw = self._forward(p, inputs, orientation)
        R_uc = fw.R_uc if orientation else None
        kept = fw if keep else None
        if not jacobian:
            return ModelOutput(fw.p_user, R_uc, None, None, fw.theta, kept)
        Jb = _numpy_jacobian(defn, fw, orientation=orientation, products=products)
        return ModelOutput(
            fw.p_user,
            R_uc,
            Jb[:, :3].transpose(2, 1, 0),
            Jb[:, 3:].transpose(2, 1, 0) if orientation else None,
            fw.theta,
            kept,
        )

    def _forward(
        self, p: Float, inputs: ModelInputs, orientation: bool
    ) -> ForwardState:
        """The numpy code's forward pass (checked inputs); one place, so that tests can
        count how often :meth:`evaluate` runs it."""
        from kinecal.models import _numpy_forward

        return _numpy_forward.forward(self.definition, p, inputs, orientation)

    def flange_frames(
        self, params: ArrayLike, inputs: ModelInputs
    ) -> tuple[Float, Float]:
        """Model flange frames in the model base, ``(R (N, 3, 3), o (N, 3))``.

        Includes every joint-angle error term; the user and cam frames are not applied.
        """
        p = np.asarray(params, dtype=np.float64)
        out = self.evaluate(p, inputs)
        from kinecal.models import _numpy_forward

        return _numpy_forward.flange_frames(self.definition, p, out.theta)

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
        from kinecal.models import _numpy_forward

        return _numpy_forward.joint_jacobian(self.definition, p, inputs, out.theta)

    # ------------------------------------------------------------------ variants
    def with_references(
        self, R_ref_base: Float | None = None, R_ref_cam: Float | None = None
    ) -> CalibrationModel:
        """A copy with other fixed reference rotations for the user / cam frames.

        A frame is ``Trans(x, y, z) · R_ref · Rz(r) Ry(w) Rx(p)``; a reference rotation
        keeps the Euler angles away from gimbal lock (``|w|`` near 90 deg). The default is
        the identity (the paper's Eq. 8-9 exactly).
        """
        m = copy.copy(self)  # the kernel's tables do not hold the reference rotations
        m.definition = self.definition.with_references(R_ref_base, R_ref_cam)
        return m

    def with_spec(self, spec: ModelSpec) -> CalibrationModel:
        """A model of the same robot with other terms (reference rotations are kept)."""
        defn = ModelDefinition.build(self.robot, spec)
        same_cams = (
            spec.markers == self.spec.markers
            and spec.cam_rotation == self.spec.cam_rotation
        )
        defn = dataclasses.replace(
            defn,
            R_ref_base=self.R_ref_base
            if spec.sets == self.spec.sets
            else defn.R_ref_base,
            R_ref_cam=self.R_ref_cam if same_cams else defn.R_ref_cam,
        )
        return CalibrationModel.from_definition(defn)


def kernel_name(model: CalibrationModel) -> str:
    """``'c'`` or ``'numpy'``: the code that evaluates ``model`` now."""
    static = _kernel.active_tables(model.definition, model._kernel_tables)
    return "c" if static is not None else "numpy"


def _numpy_jacobian(
    defn: ModelDefinition, fw: ForwardState, *, orientation: bool, products: bool
) -> Float:
    """The numpy code's Jacobian (:mod:`kinecal.models._numpy_jacobian`, loaded on first
    use: the compiled kernel evaluates most models)."""
    from kinecal.models import _numpy_jacobian as code

    return code.jacobian(
        defn, fw, orientation=orientation, products=products, alloc=_alloc
    )


def _alloc(shape: tuple[int, ...]) -> Float:
    """Uninitialised storage of the Jacobian (a test fills it with NaN instead, to show
    that :meth:`CalibrationModel.evaluate` writes every entry)."""
    return np.empty(shape)
