"""The digital twin's true robot: nominal plus errors, compliance and unmodelled effects.

A :class:`TrueRobot` is a :class:`CalibrationModel` with a richer spec than any model kinecal
fits, plus its parameters:

* kinematic errors: drawn from manufacturing tolerances (seeded) or the paper's identified
  values (Tables 3, 4, 6, 7);
* transmission errors (Eq. 16) on J1-J3, load compliance lambda* and link moments s1, s2;
* optional effects outside every fitted model: higher harmonics on J1-J3, transmission
  errors on J4-J6, off-axis link masses (general first moments on links 2-5), a thermal
  drift of the arm's scale over the measurement sequence.

The truth is saved beside simulated data (``truth.yaml``) so recovery can be checked.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
from kinecal.robot import RobotDescription, load_robot
from kinecal.typing import Float

__all__ = ["EXTRAS", "PAPER_TABLES", "TrueRobot", "paper_truth", "random_truth"]

EXTRAS = ("harmonics", "wrist", "masses", "thermal")

# The paper's identified values (mm, deg; compliance x 1e-3 as printed). Experiment 1:
# Tables 3 and 4 (3D sensor); experiment 2: Tables 6 and 7 (laser tracker). The NTM
# triplets are (J1, J2, J3) for k0, ka1, ka2, kb1, kb2 in the order of the tables' labels.
PAPER_TABLES: dict[int, dict[str, object]] = {
    1: {
        "base": (500.580, 298.611, 2638.660, -1.815, -170.153, 98.596),
        "cam": (7.096, 0.355, -348.800, 0.825, -24.750, 179.425),
        "joints": {
            1: {"a": 49.780, "alpha": -89.973},
            2: {"theta_offset": -90.066, "d": -0.0206, "a": 330.341, "alpha": 179.937},
            3: {"theta_offset": 0.0372, "d": 0.0106, "a": 34.969, "alpha": -90.001},
            4: {"theta_offset": 0.167, "d": -335.305, "a": -0.0286, "alpha": 90.037},
            5: {"theta_offset": 179.720, "d": -0.601, "a": -0.0766, "alpha": 90.103},
        },
        "ntm": {
            "k0": (0.0690, 0.250, -0.164),
            "ka1": (-0.245, -0.261, -0.695),
            "ka2": (-0.177, -0.272, -0.0487),
            "kb1": (-0.333, -0.196, -0.610),
            "kb2": (-0.0437, -0.199, -0.00706),
        },
        "lambda": (-1.159, 0.0640, 0.0582, 0.183, 0.852, -0.158),
        "s": (319.836, 1833.495),
    },
    2: {
        "base": (-1105.029, -955.794, -116.344, 21.846, -0.521, 0.166),
        "cam": (44.200, -60.458, 104.009, 0.0, 0.0, 0.0),
        "joints": {
            1: {"a": 50.202, "alpha": -89.979},
            2: {"theta_offset": -89.876, "d": -0.0121, "a": 330.049, "alpha": 179.950},
            3: {"theta_offset": -0.0293, "d": 0.2361, "a": 35.343, "alpha": -89.973},
            4: {"theta_offset": 0.720, "d": -335.152, "a": -0.232, "alpha": 90.016},
            5: {"theta_offset": -179.415, "d": -0.0786, "a": 0.125, "alpha": 90.012},
        },
        "ntm": {
            "k0": (0.158, 0.403, -0.0281),
            "ka1": (-0.120, -0.0430, -0.503),
            "ka2": (-0.0512, -0.0553, 0.144),
            "kb1": (-0.206, 0.0217, -0.418),
            "kb2": (0.0819, 0.0188, 0.183),
        },
        "lambda": (-1.289, 0.0668, 0.0522, 0.138, 0.732, -0.117),
        "s": (307.383, 1841.103),
    },
}


@dataclass
class TrueRobot:
    """A hidden true robot for the digital twin.

    Attributes
    ----------
    model : CalibrationModel with the truth's spec (a superset of the fitted models).
    params : (P,) true parameter values (SI).
    thermal_ppm_per_pose : float
        Scale drift of the arm per pose in the measurement sequence [ppm], an effect no
        model fits (0: off).
    extras : tuple of str, the unmodelled effects switched on (see :data:`EXTRAS`).
    description : str
    """

    model: CalibrationModel
    params: Float
    thermal_ppm_per_pose: float = 0.0
    extras: tuple[str, ...] = ()
    description: str = ""
    info: dict[str, object] = field(default_factory=dict)

    @property
    def robot(self) -> RobotDescription:
        return self.model.robot

    def evaluate(
        self,
        q_ctrl: Float,
        *,
        p_cam: Float | None = None,
        sequence: np.ndarray | None = None,
        orientation: bool = False,
    ) -> tuple[Float, Float | None]:
        """True cam-frame point (and orientation) in the user frame for N poses.

        ``sequence`` (N,) is the order in which poses were measured (for thermal drift).
        """
        inp = ModelInputs.make(q_ctrl, p_cam=p_cam)
        out = self.model.evaluate(self.params, inp, orientation=orientation)
        p = out.p_user
        if self.thermal_ppm_per_pose and sequence is not None:
            # The arm grows uniformly about the base origin as it warms up.
            R_b, t_b = self.model.base_frames(self.params)
            scale = 1.0 + self.thermal_ppm_per_pose * 1e-6 * np.asarray(sequence, float)
            p_base = (p - t_b[0]) @ R_b[0]
            p = (p_base * scale[:, None]) @ R_b[0].T + t_b[0]
        return p, out.R_user_cam


def _truth_spec(robot: RobotDescription, extras: tuple[str, ...]) -> ModelSpec:
    revolute = tuple(i + 1 for i, j in enumerate(robot.joints) if j.kind != "prismatic")
    ntm_joints = robot.ntm_joints
    order = 2
    if "harmonics" in extras:
        order = 4
    if "wrist" in extras:
        ntm_joints = revolute[:6]
    bodies = (2, 3, 4, 5) if "masses" in extras else ()
    return ModelSpec(
        cam_rotation=True,
        ntm_joints=ntm_joints,
        ntm_order=order,
        load=True,
        link="paper",
        link_bodies=bodies,
        name="truth",
    )


def _set(model: CalibrationModel, x: Float, name: str, value: float) -> None:
    x[model.layout.index(name)] = value


def _apply_extras(
    model: CalibrationModel, x: Float, extras: tuple[str, ...], rng: np.random.Generator
) -> None:
    """Values of the unmodelled effects (moderate: a few to ~20 micrometres each)."""
    for j in model.spec.ntm_joints:
        for h in range(3, model.spec.ntm_order + 1):
            for ab in "ab":
                _set(model, x, f"joint{j}.k{ab}{h}", rng.normal() * 4e-5)
        if j >= 4:
            for h in (1, 2):
                for ab in "ab":
                    _set(model, x, f"joint{j}.k{ab}{h}", rng.normal() * 6e-5)
    for k in model.spec.link_bodies:
        # Off-axis first moments (per unit payload weight, m): centres of mass that are not
        # on the lines the lumped model assumes.
        _set(model, x, f"link{k}.m", 0.0)
        for c in ("mx", "my", "mz"):
            _set(model, x, f"link{k}.{c}", rng.normal() * 0.03)


def paper_truth(
    experiment: int = 2,
    *,
    robot: RobotDescription | None = None,
    extras: tuple[str, ...] = (),
    seed: int = 0,
) -> TrueRobot:
    """A true LR Mate 200iD with the paper's identified values (Tables 3-4 or 6-7).

    Parameters
    ----------
    experiment : 1 (3D sensor, Tables 3-4) or 2 (laser tracker, Tables 6-7).
    extras : unmodelled effects to add (see :data:`EXTRAS`), values drawn with ``seed``.
    """
    if experiment not in PAPER_TABLES:
        raise ValueError(f"experiment must be 1 or 2; got {experiment}.")
    for e in extras:
        if e not in EXTRAS:
            raise ValueError(f"unknown extra effect {e!r}; expected some of {EXTRAS}.")
    tab = PAPER_TABLES[experiment]
    robot = robot or load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, _truth_spec(robot, extras))
    x = model.nominal.copy()
    base = np.array(tab["base"], dtype=float)
    cam = np.array(tab["cam"], dtype=float)
    for k, v in zip("xyzrwp", base):
        _set(model, x, f"base.{k}", v * 1e-3 if k in "xyz" else np.radians(v))
    if experiment == 2:
        # Table 6 gives only the reflector position; its rotation is not observable.
        cam[3:] = np.degrees(model.frame_euler(model.nominal, "cam")[0, 3:])
    for k, v in zip("xyzrwp", cam):
        _set(model, x, f"cam.{k}", v * 1e-3 if k in "xyz" else np.radians(v))
    for j, fields in tab["joints"].items():  # type: ignore[attr-defined]
        for key, v in fields.items():
            val = v * 1e-3 if key in ("a", "d") else np.radians(v)
            _set(model, x, f"joint{j}.{key}", val)
    for key, triple in tab["ntm"].items():  # type: ignore[attr-defined]
        for j, v in zip((1, 2, 3), triple):
            _set(model, x, f"joint{j}.{key}", v * 1e-3)
    for j, v in enumerate(tab["lambda"], start=1):  # type: ignore[arg-type]
        _set(model, x, f"joint{j}.lambda", v * 1e-3)
    s_mm = np.asarray(tab["s"], dtype=float)
    _set(model, x, "link.s1", float(s_mm[0]) * 1e-3)
    _set(model, x, "link.s2", float(s_mm[1]) * 1e-3)
    rng = np.random.default_rng(seed)
    _apply_extras(model, x, extras, rng)
    thermal = 0.02 if "thermal" in extras else 0.0
    return TrueRobot(
        model,
        x,
        thermal,
        tuple(extras),
        f"paper experiment {experiment} values (Tables {'3, 4' if experiment == 1 else '6, 7'})"
        + (f" + {', '.join(extras)}" if extras else ""),
        info={"experiment": experiment, "seed": seed},
    )


def random_truth(
    robot: RobotDescription,
    *,
    seed: int = 0,
    length_tol: float = 0.3e-3,
    angle_tol: float = np.radians(0.05),
    ntm_amplitude: float = 2e-4,
    compliance: float = 3e-4,
    moments: tuple[float, float] = (0.3, 1.8),
    base: Float | None = None,
    cam: Float | None = None,
    extras: tuple[str, ...] = (),
) -> TrueRobot:
    """A true robot with errors drawn from manufacturing tolerances (seeded).

    Parameters
    ----------
    length_tol, angle_tol : standard deviation of DH length and angle errors [m, rad].
    ntm_amplitude : standard deviation of each Fourier coefficient [rad].
    compliance : typical lambda* [rad/m] (drawn log-uniformly within a factor 3).
    moments : link moments s1, s2 per unit payload weight [m].
    base, cam : (6,) user and cam frames ``[x, y, z, r, w, p]`` [m, rad]; default the
        robot's nominal tool and a tracker 2 m away.
    """
    rng = np.random.default_rng(seed)
    spec = _truth_spec(robot, extras)
    if robot.self_weight is None:
        spec = ModelSpec(
            cam_rotation=True,
            ntm_joints=spec.ntm_joints,
            ntm_order=spec.ntm_order,
            load=True,
            link="none",
            link_bodies=spec.link_bodies,
            name="truth",
        )
    model = CalibrationModel(robot, spec)
    x = model.nominal.copy()
    for i, s in enumerate(model.layout.specs):
        if s.group == "joint":
            x[i] += rng.normal() * (length_tol if s.kind == "length" else angle_tol)
        elif s.group == "ntm":  # harmonics 3-4 are the unmodelled extras, set below
            high = s.field in ("ka3", "kb3", "ka4", "kb4")
            x[i] = 0.0 if high else rng.normal() * ntm_amplitude
        elif s.group == "load":
            x[i] = compliance * np.exp(rng.uniform(-1.1, 1.1))
    if robot.self_weight is not None:
        _set(model, x, "link.s1", moments[0])
        _set(model, x, "link.s2", moments[1])
    b = (
        base
        if base is not None
        else np.array([2.0, -0.4, -0.2, np.radians(160.0), 0.01, -0.02])
    )
    x[model.base_index[0]] = b
    if cam is not None:
        x[model.cam_index[0]] = cam
    _apply_extras(model, x, extras, rng)
    thermal = 0.02 if "thermal" in extras else 0.0
    return TrueRobot(
        model,
        x,
        thermal,
        tuple(extras),
        f"random tolerances (seed {seed})"
        + (f" + {', '.join(extras)}" if extras else ""),
        info={"seed": seed},
    )
