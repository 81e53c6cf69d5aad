"""An independent truth for robots imported from URDF: its own URDF writer, forward
kinematics and gravity deflection, no kinecal model code.

The arm is a 7-axis arm with the joint placement of Franka's published modified-DH table
(the built-in franka-fr3) and link masses and centres of mass chosen for the test (not
Franka's). The true robot moves every joint origin (0.2 mm, 0.03 deg), offsets every
joint zero, and each joint yields to the gravity torque of the links beyond it
(``dtheta_j = c_j tau_j``, tau from the URDF masses at the deflected pose). A tracker
sees a reflector on the flange with 10 um noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

G = 9.80665

# (name, origin xyz [m], origin rpy [rad], mass of the child link [kg], its com [m],
#  limits); every joint turns (or slides) about its own z axis.
ARM7 = [
    ("j1", (0, 0, 0.333), (0, 0, 0), 4.9, (0.003, -0.03, -0.07), (-2.7, 2.7)),
    ("j2", (0, 0, 0), (-np.pi / 2, 0, 0), 0.65, (-0.003, -0.03, 0.03), (-1.7, 1.7)),
    ("j3", (0, -0.316, 0), (np.pi / 2, 0, 0), 3.2, (0.03, 0.04, -0.07), (-2.7, 2.7)),
    ("j4", (0.0825, 0, 0), (np.pi / 2, 0, 0), 3.6, (-0.05, 0.1, 0.03), (-3.0, -0.15)),
    (
        "j5",
        (-0.0825, 0.384, 0),
        (-np.pi / 2, 0, 0),
        1.2,
        (-0.01, 0.04, -0.1),
        (-2.7, 2.7),
    ),
    ("j6", (0, 0, 0), (np.pi / 2, 0, 0), 1.7, (0.06, -0.01, 0.01), (0.55, 4.5)),
    ("j7", (0.088, 0, 0), (np.pi / 2, 0, 0), 0.75, (0.01, 0.004, 0.08), (-2.9, 2.9)),
]
# A UR-type arm: parallel shoulder, elbow and wrist-1 axes, offset wrist.
UR6 = [
    ("shoulder_pan", (0, 0, 0.163), (0, 0, 0), 3.7, (0, -0.02, 0), (-3.1, 3.1)),
    ("shoulder_lift", (0, 0, 0), (np.pi / 2, 0, 0), 8.4, (-0.21, 0, 0.14), (-3.1, 0.0)),
    ("elbow", (-0.425, 0, 0), (0, 0, 0), 2.3, (-0.19, 0, 0.02), (-2.8, 2.8)),
    ("wrist_1", (-0.392, 0, 0.134), (0, 0, 0), 1.2, (0, -0.02, 0), (-3.1, 3.1)),
    ("wrist_2", (0, -0.1, 0), (np.pi / 2, 0, 0), 1.2, (0, 0.02, 0), (-3.1, 3.1)),
    ("wrist_3", (0, 0.1, 0), (-np.pi / 2, 0, 0), 0.25, (0, 0, -0.02), (-3.1, 3.1)),
]
# A prismatic first joint (a torso lift, as TIAGo's) under a 6R arm.
TORSO = [
    ("torso_lift", (0, 0, 0.6), (0, 0, 0), 12.0, (0.0, 0.0, 0.1), (0.0, 0.35)),
    ("arm_1", (0.1, 0, 0.2), (0, 0, 0), 1.6, (0.05, 0.0, 0.02), (-2.5, 2.5)),
    (
        "arm_2",
        (0.125, 0.02, -0.015),
        (np.pi / 2, 0, 0),
        1.8,
        (0.0, 0.0, 0.06),
        (-1.5, 1.5),
    ),
    ("arm_3", (0.0, 0.0, 0.3), (-np.pi / 2, 0, 0), 1.4, (0.0, 0.05, 0.0), (-3.4, 1.5)),
    ("arm_4", (0.02, 0.0, 0.0), (np.pi / 2, 0, 0), 1.2, (0.0, 0.0, 0.1), (-0.3, 2.3)),
    (
        "arm_5",
        (-0.02, 0.0, 0.22),
        (-np.pi / 2, 0, 0),
        0.9,
        (0.0, 0.05, 0.0),
        (-2.0, 2.0),
    ),
    ("arm_6", (0.0, 0.0, 0.12), (np.pi / 2, 0, 0), 0.4, (0.0, 0.0, 0.03), (-1.4, 1.4)),
]
PRISMATIC = {"torso_lift"}
FLANGE_Z = 0.107
HAND = (0.7, (0.0, 0.0, 0.05))  # fixed to the flange: mass, com in the flange frame


def urdf_text(arm: list = ARM7, name: str = "arm7") -> str:
    """The arm as a URDF with inertials."""
    out = [f'<robot name="{name}">', '<link name="base"/>']
    parent = "base"
    for i, (name, xyz, rpy, m, c, (lo, hi)) in enumerate(arm):
        child = f"link{i + 1}"
        kind = "prismatic" if name in PRISMATIC else "revolute"
        out.append(
            f'<link name="{child}"><inertial><mass value="{m}"/>'
            f'<origin xyz="{c[0]} {c[1]} {c[2]}"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
            "</inertial></link>"
        )
        out.append(
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" '
            f'rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/><axis xyz="0 0 1"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="87" velocity="2"/></joint>'
        )
        parent = child
    out.append('<link name="flange"/>')
    out.append(
        f'<joint name="flange_joint" type="fixed"><parent link="link{len(arm)}"/>'
        f'<child link="flange"/><origin xyz="0 0 {FLANGE_Z}"/></joint>'
    )
    m, c = HAND
    out.append(
        f'<link name="hand"><inertial><mass value="{m}"/>'
        f'<origin xyz="{c[0]} {c[1]} {c[2]}"/>'
        '<inertia ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"/>'
        "</inertial></link>"
    )
    out.append(
        '<joint name="hand_joint" type="fixed"><parent link="flange"/>'
        '<child link="hand"/><origin xyz="0 0 0"/></joint>'
    )
    out.append("</robot>")
    return "\n".join(out)


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (
        np.cos(r),
        np.sin(r),
        np.cos(p),
        np.sin(p),
        np.cos(y),
        np.sin(y),
    )
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _rz(q: np.ndarray) -> np.ndarray:
    c, s = np.cos(q), np.sin(q)
    R = np.zeros((q.size, 4, 4))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1] = c, -s, s, c
    R[:, 2, 2] = R[:, 3, 3] = 1.0
    return R


def _tz(q: np.ndarray) -> np.ndarray:
    T = np.broadcast_to(np.eye(4), (q.size, 4, 4)).copy()
    T[:, 2, 3] = q
    return T


@dataclass
class TrueArm:
    """The true arm: joint origins (n, 4, 4), zero offsets, compliances [rad/(N m)]."""

    arm: list
    origins: np.ndarray
    offsets: np.ndarray
    compliance: np.ndarray
    T_tracker_base: np.ndarray
    reflector: np.ndarray  # in the flange frame [m]

    def _frames(self, q: np.ndarray):
        """Joint frames (N, n, 4, 4) after each joint, flange (N, 4, 4)."""
        N = q.shape[0]
        T = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
        frames = []
        for i, row in enumerate(self.arm):
            move = _tz if row[0] in PRISMATIC else _rz
            T = T @ self.origins[i] @ move(q[:, i] + self.offsets[i])
            frames.append(T)
        F = np.eye(4)
        F[2, 3] = FLANGE_Z
        return np.stack(frames, 1), T @ F

    def gravity_torques(self, q: np.ndarray) -> np.ndarray:
        """Torque (force for a slide) of gravity about (along) each joint axis (N, n)."""
        frames, flange = self._frames(q)
        g = np.array([0.0, 0.0, -G])
        pts, masses = [], []
        for i, (*_, m, c, _lim) in enumerate(self.arm):
            pts.append(frames[:, i, :3, :3] @ np.array(c) + frames[:, i, :3, 3])
            masses.append(m)
        pts.append(flange[:, :3, :3] @ np.array(HAND[1]) + flange[:, :3, 3])
        masses.append(HAND[0])
        tau = np.zeros(q.shape)
        n = len(self.arm)
        for j in range(n):
            z, o = frames[:, j, :3, 2], frames[:, j, :3, 3]
            # Joint j's frame is after its motion; its axis is the same line.
            for b in range(j, n + 1):  # bodies moved by joint j
                f = masses[b] * g
                if self.arm[j][0] in PRISMATIC:
                    tau[:, j] += np.einsum("ni,i->n", z, f)
                else:
                    tau[:, j] += np.einsum("ni,ni->n", z, np.cross(pts[b] - o, f))
        return tau

    def measure(
        self,
        q: np.ndarray,
        rng: np.random.Generator | None,
        noise: float = 10e-6,
        iterations: int = 3,
    ):
        """Reflector positions in the tracker frame (N, 3) [m] with noise; the torques
        at the deflected pose (``iterations`` fixed-point steps, 1: at the commanded)."""
        th = q.copy()
        for _ in range(iterations):  # converges fast: the deflection is small
            th = q + self.compliance * self.gravity_torques(th)
        _, flange = self._frames(th)
        p = flange[:, :3, :3] @ self.reflector + flange[:, :3, 3]
        p = p @ self.T_tracker_base[:3, :3].T + self.T_tracker_base[:3, 3]
        return p if rng is None else p + rng.normal(scale=noise, size=p.shape)


def true_arm(
    seed: int = 0, compliance_scale: float = 1.0, arm: list = ARM7, exact: bool = False
) -> TrueArm:
    """A drawn true arm (``exact``: the nominal geometry, tracker at the base, the
    reflector on the flange)."""
    rng = np.random.default_rng(seed)
    err = 0.0 if exact else 1.0
    origins = []
    for _, xyz, rpy, *_ in arm:
        T = np.eye(4)
        dr = rng.normal(scale=np.radians(0.03), size=3) * err
        T[:3, :3] = _rpy(*(np.array(rpy) + dr))
        T[:3, 3] = np.array(xyz) + rng.normal(scale=0.2e-3, size=3) * err
        origins.append(T)
    n = len(arm)
    offsets = rng.normal(scale=np.radians(0.05), size=n) * err
    # Joint compliance [rad/(N m)], [m/N] for a slide: the outer joints yield more.
    compliance = compliance_scale * np.linspace(2, 8, n) * 1e-5
    compliance[[r[0] in PRISMATIC for r in arm]] = 2e-7
    T_tb = np.eye(4)
    if not exact:
        T_tb[:3, :3] = _rpy(0.01, -0.02, np.radians(150))
        T_tb[:3, 3] = (2.0, -0.5, -0.3)
    refl = np.zeros(3) if exact else np.array([0.03, 0.0, 0.06])
    return TrueArm(arm, np.array(origins), offsets, compliance, T_tb, refl)


def random_poses(n: int, rng: np.random.Generator, arm: list = ARM7) -> np.ndarray:
    lo, hi = np.array([r[-1] for r in arm]).T
    margin = 0.05 * (hi - lo)
    return rng.uniform(lo + margin, hi - margin, size=(n, len(arm)))
