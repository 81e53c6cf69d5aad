"""The parameter list of a model definition, made part by part (Eq. 8-10, 16-17,
24-26): what :meth:`~kinecal.models._definition.ModelDefinition.build` assembles."""

from __future__ import annotations

import numpy as np

from kinecal.errors import ModelError
from kinecal.geometry import make_transform, rot_x, rot_z, transform_to_euler
from kinecal.models._compliance import (
    general_link_pattern,
    link_torque_pattern,
    ntm_names,
)
from kinecal.models._layout import ParamSpec
from kinecal.models._spec import ModelSpec
from kinecal.robot import DHChain, RobotDescription
from kinecal.typing import Float

__all__ = [
    "FRAME_FIELDS",
    "ROW_FIELDS",
    "Params",
    "base_frames",
    "cam_frames",
    "check_terms",
    "compliance_terms",
    "frame_group",
    "joint_rows",
    "link_pattern",
]

#: Fields of an Euler frame (Eq. 8-9), in the order of :attr:`ModelDefinition.base_idx`.
FRAME_FIELDS = ("x", "y", "z", "r", "w", "p")
#: Fields of a chain row (Eq. 10), the columns of :meth:`ModelDefinition.rows`.
ROW_FIELDS = ("theta_offset", "d", "a", "alpha", "beta")
_ROW_KINDS = ("angle", "length", "length", "angle", "angle")
# Terms of a body of the general link model: mass and first moment (frame k axes).
_BODY_TERMS = ("m", "mx", "my", "mz")


def frame_group(group: str, label: str) -> str:
    """Name prefix of a frame: ``base``, or ``base@b`` for the set labelled 'b'."""
    return group if label == "" else f"{group}@{label}"


def frame_spec(group: str, label: str, key: str) -> ParamSpec:
    return ParamSpec(
        f"{frame_group(group, label)}.{key}",
        "length" if key in "xyz" else "angle",
        group,
        label=label,
        field=key,
    )


def check_terms(robot: RobotDescription, spec: ModelSpec) -> None:
    """Refuse terms the robot cannot have."""
    n = robot.n_joints
    for j in spec.hayati:
        if not 2 <= j <= n - 1:
            raise ModelError(f"Hayati rows are for joints 2..{n - 1}; got joint {j}.")
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


class Params:
    """The parameters of a definition in the making: their specs and nominal values."""

    def __init__(self) -> None:
        self.specs: list[ParamSpec] = []
        self.nominal: list[float] = []

    def add(self, param: ParamSpec, value: float = 0.0) -> int:
        """Append a parameter; its index."""
        self.specs.append(param)
        self.nominal.append(float(value))
        return len(self.specs) - 1


def base_frames(
    chain: DHChain, spec: ModelSpec, params: Params
) -> tuple[Float, list[list[int]]]:
    """Frames user <- base, one per set (Eq. 8): the nominal model base (joint 1's theta
    offset and d are absorbed by the base frame, Eq. 10) and the parameters' indices."""
    off1, d1 = chain.theta_offset[0], chain.d[0]
    T_base_b0 = chain.T_base_0 @ make_transform(rot_z(off1), [0.0, 0.0, d1])
    base0 = transform_to_euler(T_base_b0)  # Eq. (8) at the nominal base
    base_idx = [
        [
            params.add(frame_spec("base", lab, key), v)
            for key, v in zip(FRAME_FIELDS, base0)
        ]
        for lab in spec.sets
    ]
    return T_base_b0, base_idx


def joint_rows(
    chain: DHChain, spec: ModelSpec, params: Params
) -> tuple[np.ndarray, Float]:
    """Joint rows (Eq. 10): the parameter of each row value (-1 for none) and the d
    moved out of Hayati rows into the next row."""
    n = len(chain.d)
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
            d_shift[i + 1] += d * np.cos(al)  # Tz(d) slides to the next parallel axis
            fields = {"theta_offset": off, "a": a, "alpha": al, "beta": 0.0}
        else:
            fields = {"theta_offset": off, "d": d, "a": a, "alpha": al}
        for c, key in enumerate(ROW_FIELDS):
            if key in fields:
                row = ParamSpec(
                    f"joint{j}.{key}", _ROW_KINDS[c], "joint", joint=j, field=key
                )
                row_idx[i, c] = params.add(row, fields[key])
    return row_idx, d_shift


def cam_frames(
    robot: RobotDescription,
    chain: DHChain,
    spec: ModelSpec,
    d_shift: Float,
    params: Params,
) -> tuple[Float, tuple[str, ...], list[list[int]]]:
    """Frames flange <- cam, one per marker (Eq. 9): the last row keeps only its
    rotation; its offset, d, a, alpha, the physical flange and the nominal tool become
    the starting value of T_flange_cam. Returns it, the fields and their indices."""
    n = len(chain.d)
    T_fc = (
        make_transform(
            rot_z(chain.theta_offset[-1]), [0.0, 0.0, chain.d[-1] + d_shift[n - 1]]
        )
        @ make_transform(rot_x(chain.alpha[-1]), [chain.a[-1], 0.0, 0.0])
        @ chain.T_n_flange
        @ robot.T_flange_tool
    )
    cam0 = transform_to_euler(T_fc)
    cam_keys = FRAME_FIELDS if spec.cam_rotation else FRAME_FIELDS[:3]
    cam_idx = [
        [
            params.add(frame_spec("cam", m, key), cam0[FRAME_FIELDS.index(key)])
            for key in cam_keys
        ]
        for m in spec.markers
    ]
    return T_fc, tuple(cam_keys), cam_idx


def compliance_terms(
    spec: ModelSpec, n: int, params: Params
) -> tuple[tuple[str, ...], int, int, int]:
    """The transmission (Eq. 16-17), payload (Eq. 24) and link-weight terms (Eq. 25-26):
    the Fourier term names and where each group starts."""
    ntm_terms = ntm_names(spec.ntm_order, spec.ntm_offset) if spec.ntm_joints else []
    ntm_start = len(params.specs)
    for j in spec.ntm_joints:  # Eq. (16-17): one series per joint
        for coef in ntm_terms:
            params.add(ParamSpec(f"joint{j}.{coef}", "ntm", "ntm", joint=j, field=coef))
    load_start = len(params.specs)
    if spec.load:  # Eq. (24): lambda* per joint
        for j in range(1, n + 1):
            name = f"joint{j}.lambda"
            params.add(ParamSpec(name, "compliance", "load", joint=j, field="lambda"))
    link_start = len(params.specs)
    lumped: list[str] = []
    if spec.link == "paper":  # Eq. (25-26): s1*, s2*
        lumped = ["s1", "s2"]
    elif spec.link == "rfcm":
        lumped = ["s1", "s2_shoulder", "s2_elbow"]
    for term in lumped:
        params.add(ParamSpec(f"link.{term}", "moment", "link", field=term))
    for k in spec.link_bodies:  # the general form of Eq. (25), per body
        for term in _BODY_TERMS:
            kind = "ratio" if term == "m" else "moment"
            params.add(ParamSpec(f"link{k}.{term}", kind, "link", joint=k, field=term))
    return tuple(ntm_terms), ntm_start, load_start, link_start


def link_pattern(
    robot: RobotDescription, chain: DHChain, spec: ModelSpec, n_link: int
) -> tuple[float, list[tuple[int, int]]]:
    """The sign of the shoulder row's ``a`` and, where a link parameter s_k acts on
    joint j (the deflection holds the product lambda*_j s_k), every such (joint, column
    of the link basis) pair."""
    sw = robot.self_weight
    x_sign = 1.0
    if sw is not None and spec.link in ("paper", "rfcm"):
        x_sign = 1.0 if chain.a[sw.shoulder - 1] >= 0 else -1.0
    pattern: list[tuple[int, int]] = []
    if spec.link in ("paper", "rfcm") and sw is not None:
        pattern += link_torque_pattern(spec.link, sw.shoulder, sw.elbow)
    if spec.link_bodies:
        first = n_link - 4 * len(spec.link_bodies)
        pattern += [
            (j, first + k)
            for j, k in general_link_pattern(spec.link_bodies, chain.prismatic.copy())
        ]
    return x_sign, pattern
