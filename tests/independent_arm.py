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

# (name, origin xyz [m], origin rpy [rad], mass of the child link [kg], its com [m])
ARM7 = [
    ("j1", (0, 0, 0.333), (0, 0, 0), 4.9, (0.003, -0.03, -0.07)),
    ("j2", (0, 0, 0), (-np.pi / 2, 0, 0), 0.65, (-0.003, -0.03, 0.03)),
    ("j3", (0, -0.316, 0), (np.pi / 2, 0, 0), 3.2, (0.03, 0.04, -0.07)),
    ("j4", (0.0825, 0, 0), (np.pi / 2, 0, 0), 3.6, (-0.05, 0.1, 0.03)),
    ("j5", (-0.0825, 0.384, 0), (-np.pi / 2, 0, 0), 1.2, (-0.01, 0.04, -0.1)),
    ("j6", (0, 0, 0), (np.pi / 2, 0, 0), 1.7, (0.06, -0.01, 0.01)),
    ("j7", (0.088, 0, 0), (np.pi / 2, 0, 0), 0.75, (0.01, 0.004, 0.08)),
]
FLANGE_Z = 0.107
HAND = (0.7, (0.0, 0.0, 0.05))  # fixed to the flange: mass, com in the flange frame
LIMITS = [(-2.7, 2.7), (-1.7, 1.7), (-2.7, 2.7), (-3.0, -0.15), (-2.7, 2.7)]
LIMITS += [(0.55, 4.5), (-2.9, 2.9)]


def urdf_text() -> str:
    """The arm as a URDF with inertials."""
    out = ['<robot name="arm7">', '<link name="base"/>']
    parent = "base"
    for i, (name, xyz, rpy, m, c) in enumerate(ARM7):
        child = f"link{i + 1}"
        lo, hi = LIMITS[i]
        out.append(
            f'<link name="{child}"><inertial><mass value="{m}"/>'
            f'<origin xyz="{c[0]} {c[1]} {c[2]}"/>'
            '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'
            "</inertial></link>"
        )
        out.append(
            f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz[0]} {xyz[1]} {xyz[2]}" '
            f'rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/><axis xyz="0 0 1"/>'
            f'<limit lower="{lo}" upper="{hi}" effort="87" velocity="2"/></joint>'
        )
        parent = child
    out.append('<link name="flange"/>')
    out.append(
        '<joint name="flange_joint" type="fixed"><parent link="link7"/>'
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


@dataclass
class TrueArm:
    """The true arm: joint origins (7, 4, 4), zero offsets, compliances [rad/(N m)]."""

    origins: np.ndarray
    offsets: np.ndarray
    compliance: np.ndarray
    T_tracker_base: np.ndarray
    reflector: np.ndarray  # in the flange frame [m]

    def _frames(self, q: np.ndarray):
        """Joint frames (N, 7, 4, 4) after each joint, flange (N, 4, 4)."""
        N = q.shape[0]
        T = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
        frames = []
        for i in range(7):
            T = T @ self.origins[i] @ _rz(q[:, i] + self.offsets[i])
            frames.append(T)
        F = np.eye(4)
        F[2, 3] = FLANGE_Z
        return np.stack(frames, 1), T @ F

    def gravity_torques(self, q: np.ndarray) -> np.ndarray:
        """Torque of gravity about each joint axis (N, 7) [N m]."""
        frames, flange = self._frames(q)
        g = np.array([0.0, 0.0, -G])
        pts, masses = [], []
        for i, (*_, m, c) in enumerate(ARM7):
            pts.append(frames[:, i, :3, :3] @ np.array(c) + frames[:, i, :3, 3])
            masses.append(m)
        pts.append(flange[:, :3, :3] @ np.array(HAND[1]) + flange[:, :3, 3])
        masses.append(HAND[0])
        tau = np.zeros(q.shape)
        for j in range(7):
            z, o = frames[:, j, :3, 2], frames[:, j, :3, 3]
            for b in range(j, 8):  # bodies moved by joint j
                f = masses[b] * g
                tau[:, j] += np.einsum("ni,ni->n", z, np.cross(pts[b] - o, f))
        return tau

    def measure(self, q: np.ndarray, rng: np.random.Generator, noise: float = 10e-6):
        """Reflector positions in the tracker frame (N, 3) [m] with noise."""
        th = q.copy()
        for _ in range(3):  # the deflected pose's torques (converges quadratically)
            th = q + self.compliance * self.gravity_torques(th)
        _, flange = self._frames(th)
        p = flange[:, :3, :3] @ self.reflector + flange[:, :3, 3]
        p = p @ self.T_tracker_base[:3, :3].T + self.T_tracker_base[:3, 3]
        return p + rng.normal(scale=noise, size=p.shape)


def true_arm(seed: int = 0, compliance_scale: float = 1.0) -> TrueArm:
    rng = np.random.default_rng(seed)
    origins = []
    for _, xyz, rpy, *_ in ARM7:
        T = np.eye(4)
        T[:3, :3] = _rpy(*(np.array(rpy) + rng.normal(scale=np.radians(0.03), size=3)))
        T[:3, 3] = np.array(xyz) + rng.normal(scale=0.2e-3, size=3)
        origins.append(T)
    offsets = rng.normal(scale=np.radians(0.05), size=7)
    # Joint compliance [rad/(N m)]: the shoulder and elbow yield most.
    compliance = compliance_scale * np.array([2, 3, 3, 4, 6, 6, 8]) * 1e-5
    T_tb = np.eye(4)
    T_tb[:3, :3] = _rpy(0.01, -0.02, np.radians(150))
    T_tb[:3, 3] = (2.0, -0.5, -0.3)
    return TrueArm(
        np.array(origins), offsets, compliance, T_tb, np.array([0.03, 0.0, 0.06])
    )


def random_poses(n: int, rng: np.random.Generator) -> np.ndarray:
    lo, hi = np.array(LIMITS).T
    return rng.uniform(lo + 0.1, hi - 0.1, size=(n, 7))
