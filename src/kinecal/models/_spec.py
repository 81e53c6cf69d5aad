"""Which terms a model has: the presets of DESIGN §6 and their options.

=========  =====================================================  ==============
preset     terms                                                  6-axis, sensor
=========  =====================================================  ==============
kinematic  unified kinematic model (Eq. 7-10)                     30
ntm        + extended NTM, joints 1-3, order 2 (Eq. 14-17)         45
rfcm       + load compliance (Eq. 24) + link self-weight with      39
           independent moments (J2 upper arm, J2 forearm, J3)
full       + NTM + load + link self-weight s1, s2 (Eq. 25-26)     53
=========  =====================================================  ==============
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from kinecal._record import Record
from kinecal.errors import ModelError
from kinecal.robot import RobotDescription

__all__ = ["PRESETS", "ModelSpec", "parallel_pairs"]

PRESETS = ("kinematic", "ntm", "rfcm", "full")
LINK_MODELS = ("none", "paper", "rfcm", "general")


@dataclass(frozen=True, eq=False, repr=False)
class ModelSpec(Record):
    """Terms and options of a calibration model.

    Attributes
    ----------
    cam_rotation : bool
        Identify the rotation of ``T_flange_cam`` (False for position-only data: 27 params).
    hayati : tuple of int
        1-based joints whose row becomes Hayati's ``Rz Tx Rx Ry(beta)`` (no d); use it for
        a joint whose axis is parallel to the next one (LR Mate: 2).
    ntm_joints : tuple of int
        1-based joints with a Fourier transmission-error series (Eq. 16); empty: no NTM.
    ntm_order : int
        Order N of the series (2 in the paper).
    ntm_offset : bool
        Include the constant term k0 (redundant with the joint offsets; kept for the paper's
        parameter count, found and fixed by the identifiability analysis).
    load : bool
        Payload compliance, lambda* per joint (Eq. 18-24).
    link : {'none', 'paper', 'rfcm', 'general'}
        Link self-weight: the paper's two lumped moments s1, s2 (Eq. 25-26), three
        independent moments (the RFCM comparison model), or the general form: mass and
        first moment of each body in ``link_bodies`` (any robot, any base tilt).
    link_bodies : tuple of int
        Bodies (DH frame numbers) with general mass and first-moment terms: the whole
        link model for ``link='general'``, or terms added to the lumped 'paper'/'rfcm'
        moments (the digital twin uses this for link masses outside the paper's model).
    sets : tuple of str
        Labels of measurement sessions; each has its own user frame.
    markers : tuple of str
        Labels of tool markers; each has its own cam frame.
    name : str
        Preset name or ``'custom'``.
    """

    cam_rotation: bool = True
    hayati: tuple[int, ...] = ()
    ntm_joints: tuple[int, ...] = ()
    ntm_order: int = 2
    ntm_offset: bool = True
    load: bool = False
    link: str = "none"
    link_bodies: tuple[int, ...] = ()
    sets: tuple[str, ...] = ("",)
    markers: tuple[str, ...] = ("",)
    name: str = "custom"

    def __post_init__(self) -> None:
        if self.link not in LINK_MODELS:
            raise ModelError(f"link must be one of {LINK_MODELS}; got {self.link!r}.")
        if self.ntm_order < 1 and self.ntm_joints:
            raise ModelError(f"ntm_order must be >= 1; got {self.ntm_order}.")
        if not self.sets or not self.markers:
            raise ModelError("a model needs at least one set and one marker label.")
        if len(set(self.sets)) != len(self.sets) or len(set(self.markers)) != len(
            self.markers
        ):
            raise ModelError("set and marker labels must be unique.")
        if self.link == "general" and not self.link_bodies:
            raise ModelError("the general link model needs link_bodies, e.g. (2, 3).")
        if (self.link != "none" or self.link_bodies) and not self.load:
            raise ModelError(
                "link self-weight terms share lambda* with the load term; enable load."
            )

    @classmethod
    def preset(
        cls,
        name: str,
        *,
        cam_rotation: bool = True,
        sets: tuple[str, ...] = ("",),
        markers: tuple[str, ...] = ("",),
        ntm_joints: tuple[int, ...] = (1, 2, 3),
        ntm_order: int = 2,
        hayati: tuple[int, ...] = (),
        has_self_weight: bool = True,
        link_bodies: tuple[int, ...] = (),
    ) -> ModelSpec:
        """One of :data:`PRESETS`. ``has_self_weight=False`` drops the lumped link terms;
        ``link_bodies`` (the robot's bodies with known masses, used without the lumped
        layout) makes the link terms of 'rfcm' and 'full' the general model's."""
        if name not in PRESETS:
            raise ModelError(
                f"unknown model {name!r}; expected one of {', '.join(PRESETS)}."
            )
        base = cls(
            cam_rotation=cam_rotation,
            sets=sets,
            markers=markers,
            hayati=hayati,
            name=name,
        )
        if name == "kinematic":
            return base
        if name == "ntm":
            return replace(base, ntm_joints=ntm_joints, ntm_order=ntm_order)
        link = (
            "none" if not has_self_weight else ("rfcm" if name == "rfcm" else "paper")
        )
        bodies: tuple[int, ...] = ()
        if link == "none" and link_bodies:
            link, bodies = "general", tuple(link_bodies)
        if name == "rfcm":
            return replace(base, load=True, link=link, link_bodies=bodies)
        return replace(
            base,
            ntm_joints=ntm_joints,
            ntm_order=ntm_order,
            load=True,
            link=link,
            link_bodies=bodies,
        )

    def with_(self, **changes: object) -> ModelSpec:
        """A copy with some fields changed."""
        return replace(self, **changes)  # type: ignore[arg-type]


def parallel_pairs(robot: RobotDescription) -> tuple[int, ...]:
    """Joints j (2..n-1) whose axis is parallel to axis j + 1: candidates for Hayati rows."""
    ch = robot.dh_chain()
    n = robot.n_joints
    return tuple(j for j in range(2, n) if abs(np.sin(ch.alpha[j - 1])) < 1e-9)
