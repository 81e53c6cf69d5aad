"""Robot description: joint table (standard DH or Craig MDH), coupling, limits, frames.

A :class:`RobotDescription` holds everything in SI (m, rad). It can always be turned into a
standard-DH chain (:meth:`RobotDescription.dh_chain`), which the models use:

.. math:: T_{base,flange}(\\theta) = T_{base,0} \\prod_i R_z(\\theta_i + o_i) T_z(d_i) T_x(a_i)
          R_x(\\alpha_i) \\; T_{n,flange}

``T_{base,0}`` is the robot's fixed frame 0 of the joint table in its base frame
(``RobotDescription.T_base_0``: identity, or a URDF's base link to the DH frame on the
first axis). A Craig (modified) DH row ``Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)``
is re-grouped exactly into standard rows: the first ``Rx Tx`` joins the fixed prefix
``T_base_0`` and row i takes ``a``, ``alpha`` of MDH row i + 1.

Controller angles ``q_ctrl`` (what the data holds) map to kinematic angles through the
coupling matrix: ``theta = C @ q_ctrl`` (FANUC: ``theta3 = J3 + J2``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal._record import Record
from kinecal.errors import ConfigError
from kinecal.geometry import make_transform, rot_x
from kinecal.typing import ArrayLike, Float, Pose

__all__ = [
    "DHChain",
    "JointSpec",
    "LinkMass",
    "RobotDescription",
    "SelfWeightSpec",
    "dh_transforms",
]

NDArrayBool = np.ndarray  # (n,) bool


@dataclass(frozen=True, eq=False, repr=False)
class JointSpec(Record):
    """One joint row, SI units.

    For ``convention='dh'`` the row is ``Rz(q + theta_offset) Tz(d) Tx(a) Rx(alpha)``;
    for ``'mdh'`` (Craig) it is ``Rx(alpha) Tx(a) Rz(q + theta_offset) Tz(d)``, i.e. ``a``
    and ``alpha`` belong to the previous link. A prismatic joint adds ``q`` to ``d``.
    """

    name: str
    theta_offset: float
    d: float
    a: float
    alpha: float
    kind: str = "revolute"  # or "prismatic"
    limits: tuple[float, float] = (-np.inf, np.inf)
    velocity: float | None = None  # rad/s (m/s if prismatic), when the maker states it
    effort: float | None = None  # N m (N if prismatic), when stated


@dataclass(frozen=True, eq=False, repr=False)
class SelfWeightSpec(Record):
    """Which joints carry the paper's lumped link self-weight model (Eq. 25-26).

    ``shoulder`` and ``elbow`` are 1-based joint numbers of the two parallel pitch axes
    (LR Mate: J2 and J3); the forearm moment points from the elbow axis towards the origin
    of standard-DH frame ``wrist_frame`` (the wrist centre of a spherical wrist).
    """

    shoulder: int = 2
    elbow: int = 3
    wrist_frame: int = 4


@dataclass(frozen=True, eq=False, repr=False)
class LinkMass(Record):
    """Mass and centre of mass of the body rigid with standard-DH frame ``frame``.

    The general link self-weight model (Eq. 25 for N links) starts from these: body k
    (moved by joints 1..k) weighs ``mass`` [kg] with its centre of mass at ``com`` (3,)
    [m] in DH frame k. ``import-urdf`` lumps the URDF inertials of every link between
    joint k and joint k + 1 (fixed joints included) into body k.
    """

    frame: int
    mass: float
    com: tuple[float, float, float]


@dataclass(frozen=True, eq=False, repr=False)
class DHChain(Record):
    """A robot as a standard-DH chain between two fixed frames (all SI).

    Attributes
    ----------
    T_base_0 : (4, 4) fixed transform from the robot base to the first DH frame (the
        robot's ``T_base_0``, then an MDH table's first ``Rx Tx``).
    theta_offset, d, a, alpha : (n,) standard DH rows.
    prismatic : (n,) bool, joint variable adds to ``d`` instead of ``theta``.
    T_n_flange : (4, 4) physical flange in the last DH frame.
    """

    T_base_0: Pose
    theta_offset: Float
    d: Float
    a: Float
    alpha: Float
    prismatic: NDArrayBool
    T_n_flange: Pose

    @property
    def n_joints(self) -> int:
        return int(self.theta_offset.shape[0])


def _ntm_joints(robot: RobotDescription) -> tuple[int, ...]:
    """:attr:`RobotDescription.ntm_joints`: the first three revolute joints."""
    revolute = [i for i, j in enumerate(robot.joints) if j.kind != "prismatic"]
    return tuple(i + 1 for i in revolute[:3])


def dh_transforms(
    theta: ArrayLike, d: ArrayLike, a: ArrayLike, alpha: ArrayLike
) -> Pose:
    """Standard DH row transforms ``Rz(theta) Tz(d) Tx(a) Rx(alpha)``, broadcast (..., 4, 4)."""
    theta, d, a, alpha = np.broadcast_arrays(
        *(np.asarray(x, dtype=np.float64) for x in (theta, d, a, alpha))
    )
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    T = np.zeros((*theta.shape, 4, 4))
    T[..., 0, 0] = ct
    T[..., 0, 1] = -st * ca
    T[..., 0, 2] = st * sa
    T[..., 0, 3] = a * ct
    T[..., 1, 0] = st
    T[..., 1, 1] = ct * ca
    T[..., 1, 2] = -ct * sa
    T[..., 1, 3] = a * st
    T[..., 2, 1] = sa
    T[..., 2, 2] = ca
    T[..., 2, 3] = d
    T[..., 3, 3] = 1.0
    return T


@dataclass(frozen=True, eq=False, repr=False)
class RobotDescription(Record):
    """A serial robot, SI units throughout.

    Attributes
    ----------
    name : str
    convention : {'dh', 'mdh'}
        Convention of ``joints`` (how the rows were given).
    joints : tuple of JointSpec
    coupling : (n, n) ndarray
        ``theta = coupling @ q_ctrl``; identity when the controller reports DH angles.
    T_flange_tool : (4, 4) ndarray
        Nominal tool (reflector, sensor) in the physical flange frame.
    T_n_flange : (4, 4) ndarray
        Physical flange in the last joint frame of ``convention`` (e.g. a FANUC faceplate).
    gravity : (3,) ndarray
        Gravity acceleration in the base frame [m/s^2].
    payload_kg : float or None
        Mass of the payload at the tool, if known (converts compliance to rad/(N·m)).
    rated_payload_kg : float or None
        The maker's rated payload, if known (a heavier payload in the data is reported).
    self_weight : SelfWeightSpec or None
        Joints of the paper's link self-weight model; ``None`` if it does not apply.
    prior_sigma : dict
        Prior standard deviations (SI) by ``(group, kind)``, overriding the defaults of
        the identification (e.g. ``{("joint", "length"): 5e-3}`` for a robot whose
        geometry departs more from its nominal table).
    source : str
        Where the data came from (file path or built-in name).
    link_masses : tuple of LinkMass
        Link masses and centres of mass (from a URDF's inertials) for the general link
        self-weight model; used when ``self_weight`` is None. Empty: none known.
    T_base_0 : (4, 4) ndarray
        Frame 0 of the joint table in the robot base frame (YAML ``frame0``): identity,
        or where ``import-urdf`` put DH frame 0 on a first axis that is not the base
        link's z axis, so that poses stay in the URDF's base link.
    """

    name: str
    convention: str
    joints: tuple[JointSpec, ...]
    coupling: Float
    T_flange_tool: Pose = field(default_factory=lambda: np.eye(4))
    T_n_flange: Pose = field(default_factory=lambda: np.eye(4))
    gravity: Float = field(default_factory=lambda: np.array([0.0, 0.0, -9.80665]))
    payload_kg: float | None = None
    self_weight: SelfWeightSpec | None = None
    source: str = ""
    prior_sigma: dict[tuple[str, str], float] = field(default_factory=dict)
    rated_payload_kg: float | None = None
    link_masses: tuple[LinkMass, ...] = ()
    T_base_0: Pose = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        n = len(self.joints)
        M = np.asarray(self.T_base_0)
        R = M[:3, :3] if M.shape == (4, 4) else np.zeros((3, 3))
        if not (
            np.all(np.isfinite(M))
            and np.allclose(R.T @ R, np.eye(3), atol=1e-9)
            and np.linalg.det(R) > 0
            and np.array_equal(M[3], [0.0, 0.0, 0.0, 1.0])
        ):
            raise ConfigError(
                f"{self.name}: T_base_0 (frame0) must be a rigid transform, shape (4, "
                f"4); got {np.array2string(M, precision=6, separator=', ')}."
            )
        if n < 2:
            raise ConfigError(f"{self.name}: a robot needs at least 2 joints; got {n}.")
        if self.convention not in ("dh", "mdh"):
            raise ConfigError(
                f"{self.name}: convention must be 'dh' or 'mdh'; got {self.convention!r}."
            )
        if self.coupling.shape != (n, n):
            raise ConfigError(
                f"{self.name}: coupling must be {n}x{n}; got {self.coupling.shape}."
            )
        if abs(np.linalg.det(self.coupling)) < 1e-9:
            raise ConfigError(f"{self.name}: the joint coupling matrix is singular.")
        frames = [b.frame for b in self.link_masses]
        if len(set(frames)) != len(frames) or not all(1 <= k <= n for k in frames):
            raise ConfigError(
                f"{self.name}: link masses need distinct DH frames 1..{n}; got {frames}."
            )
        g = np.linalg.norm(self.gravity)
        if not np.isfinite(g) or g <= 0:
            raise ConfigError(
                f"{self.name}: gravity must be a non-zero vector; got {self.gravity}."
            )

    # ------------------------------------------------------------------ joint spaces
    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def joint_names(self) -> list[str]:
        return [j.name for j in self.joints]

    @property
    def link_bodies(self) -> tuple[int, ...]:
        """DH frames of the bodies with a known mass whose weight some joint feels (the
        general link model's bodies): body 1 hangs from joint 1 alone, and a revolute
        joint 1 about the gravity line carries no torque from it."""
        ch = self.dh_chain()
        g = self.gravity / np.linalg.norm(self.gravity)
        silent = (
            {1}
            if (
                not ch.prismatic[0]
                and abs(abs(float(ch.T_base_0[:3, 2] @ g)) - 1) < 1e-9
            )
            else set()
        )
        return tuple(
            b.frame for b in self.link_masses if b.mass > 0 and b.frame not in silent
        )

    @property
    def prismatic(self) -> NDArrayBool:
        return np.array([j.kind == "prismatic" for j in self.joints])

    @property
    def ntm_joints(self) -> tuple[int, ...]:
        """The joints (1-based) that carry the transmission series by default: the first
        three revolute joints (a prismatic joint has no Fourier series in its angle).
        Choosing the three with the longest mean lever arm to the tool (J1, J2, J4 of a
        7-axis arm) was tried: with the selection inside every fold it was worse on the
        shipped FR3 (leave-one-out 1.219 against 1.168 mm) and TIAGo sets (4.340
        against 4.217 mm)."""
        return _ntm_joints(self)

    @property
    def limits(self) -> Float:
        """Joint limits in controller space, shape (n, 2) [rad or m]."""
        return np.array([j.limits for j in self.joints], dtype=np.float64)

    def theta_from_ctrl(self, q_ctrl: ArrayLike) -> Float:
        """Kinematic joint values ``theta = C q_ctrl`` for (..., n) controller values."""
        q = np.asarray(q_ctrl, dtype=np.float64)
        return q @ self.coupling.T

    def ctrl_from_theta(self, theta: ArrayLike) -> Float:
        """Controller values ``q_ctrl = C^-1 theta`` for (..., n) kinematic values."""
        th = np.asarray(theta, dtype=np.float64)
        return th @ np.linalg.inv(self.coupling).T

    # ------------------------------------------------------------------ DH chain
    def dh_chain(self) -> DHChain:
        """The robot as a standard-DH chain (MDH rows are regrouped exactly)."""
        js = self.joints
        off = np.array([j.theta_offset for j in js])
        d = np.array([j.d for j in js])
        a = np.array([j.a for j in js])
        al = np.array([j.alpha for j in js])
        pris = self.prismatic
        T_b0 = np.array(self.T_base_0, dtype=np.float64)
        if self.convention == "dh":
            return DHChain(T_b0, off, d, a, al, pris, self.T_n_flange.copy())
        # Craig: prod_i Rx(al_i) Tx(a_i) Rz(th_i) Tz(d_i)
        #      = [Rx(al_1) Tx(a_1)] prod_i [Rz(th_i) Tz(d_i) Tx(a_{i+1}) Rx(al_{i+1})] ...
        #        with Rx Tx = Tx Rx (same axis), and the last row has a = alpha = 0.
        T_base_0 = (
            T_b0
            @ make_transform(rot_x(al[0]), [0.0, 0.0, 0.0])
            @ make_transform(np.eye(3), [a[0], 0.0, 0.0])
        )
        a_dh = np.append(a[1:], 0.0)
        al_dh = np.append(al[1:], 0.0)
        return DHChain(T_base_0, off, d, a_dh, al_dh, pris, self.T_n_flange.copy())

    def fk_flange(self, q_ctrl: ArrayLike) -> Pose:
        """Nominal physical flange pose in the base frame, ``T_base_flange`` (..., 4, 4).

        Parameters
        ----------
        q_ctrl : array_like, shape (..., n)
            Controller joint values [rad, m for prismatic].
        """
        q = np.asarray(q_ctrl, dtype=np.float64)
        if q.shape[-1:] != (self.n_joints,):
            raise ValueError(
                f"q_ctrl must have shape (..., {self.n_joints}) for {self.name}; got {q.shape}."
            )
        ch = self.dh_chain()
        theta = self.theta_from_ctrl(q)
        rot = np.where(ch.prismatic, ch.theta_offset, ch.theta_offset + theta)
        dd = np.where(ch.prismatic, ch.d + theta, ch.d)
        A = dh_transforms(rot, dd, ch.a, ch.alpha)  # (..., n, 4, 4)
        T = np.broadcast_to(ch.T_base_0, (*q.shape[:-1], 4, 4)).copy()
        for i in range(self.n_joints):  # loop over joints, not samples
            T = T @ A[..., i, :, :]
        return T @ ch.T_n_flange

    def fk_tool(self, q_ctrl: ArrayLike) -> Pose:
        """Nominal tool pose ``T_base_tool = T_base_flange @ T_flange_tool`` (..., 4, 4)."""
        return self.fk_flange(q_ctrl) @ self.T_flange_tool
