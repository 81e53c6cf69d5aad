"""A digital twin of any robot: a plausible truth drawn around its description, and a
laser-tracker experiment on it (``kinecal simulate --robot``).

The truth (:func:`robot_truth`) has

* geometric deviations of every DH row and zero offsets (manufacturing tolerances);
* transmission errors (Eq. 16) on the first three revolute joints;
* gravity compliance: the link self-weight of the robot's own layout, the lumped one
  (``self_weight``) or the general one from its link masses (``link_masses``, each mass
  and first moment off the nominal by about 10 %), and joint compliances scaled so that
  each joint yields about ``deflection`` under the largest gravity torque it carries
  (at most 10x the median joint's compliance);
* a payload at the tool (the robot's ``payload_kg``, or a 1 kg tool).

:func:`robot_experiment` measures it with a laser tracker at given (a plan's) or random
poses within the joint limits.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinecal.measurement import Measurements
from kinecal.models import CalibrationModel
from kinecal.robot import RobotDescription
from kinecal.robot._gravity import gravity_torques, random_joint_poses
from kinecal.simulation._experiments import Experiment, _split
from kinecal.simulation._instruments import LaserTracker
from kinecal.simulation._planning import PlannedPoses
from kinecal.simulation._truth import TrueRobot, _apply_extras, _truth_spec
from kinecal.typing import Float

__all__ = ["gravity_torques", "random_joint_poses", "robot_experiment", "robot_truth"]

_TORQUE_POSES = 400


def robot_truth(
    robot: RobotDescription,
    *,
    seed: int = 0,
    length_tol: float = 0.2e-3,
    angle_tol: float = np.radians(0.03),
    ntm_amplitude: float = 1e-4,
    deflection: float = np.radians(0.02),
    mass_error: float = 0.1,
    base: Float | None = None,
    extras: tuple[str, ...] = (),
) -> TrueRobot:
    """A true robot drawn around ``robot`` (seeded); see the module docstring.

    Parameters
    ----------
    length_tol, angle_tol : std of the DH length and angle deviations [m, rad].
    ntm_amplitude : std of each Fourier coefficient [rad].
    deflection : the typical largest gravity deflection of a joint [rad] (the joint
        compliances are drawn within a factor 1.5 of it over the largest torque).
    mass_error : relative std of the link masses and first moments against the file's.
    base : (6,) the robot base in the tracker frame [m, rad]; default 2 m away.
    """
    rng = np.random.default_rng(seed)
    spec = _truth_spec(robot, extras)
    lumped = robot.self_weight is not None
    bodies = tuple(sorted(set(robot.link_bodies) | set(spec.link_bodies)))
    spec = replace(
        spec,
        link="paper" if lumped else ("general" if bodies else "none"),
        link_bodies=spec.link_bodies if lumped else bodies,
    )
    model = CalibrationModel(robot, spec)
    x = model.nominal.copy()
    L = model.layout
    for i, s in enumerate(L.specs):
        if s.group == "joint":
            x[i] += rng.normal() * (length_tol if s.kind == "length" else angle_tol)
        elif s.group == "ntm":
            x[i] = 0.0 if s.field[-1] in "34" else rng.normal() * ntm_amplitude
        elif s.group == "link" and s.joint in robot.link_bodies:
            x[i] *= 1.0 + mass_error * rng.normal()
    # Joint compliance from the gravity torques the joints carry.
    q = random_joint_poses(robot, _TORQUE_POSES, rng)
    tau = np.abs(gravity_torques(robot, q)).max(axis=0)
    if lumped:  # the lumped moments stand for the arm: a typical 6-axis arm's
        x[L.index("link.s1")], x[L.index("link.s2")] = 0.3, 1.8
        tau = tau + 2.0 * (tau > 1e-9)
    carried = tau > 1e-6 * max(tau.max(), 1e-300)
    typical = deflection / np.median(tau[carried]) if carried.any() else 3e-4
    # A joint that carries almost no torque (a wrist whose links' centres of mass lie
    # on its axis, with the tool on it too) is not that much softer: at most 10x the
    # typical compliance (deflection / its tiny torque put an xArm 6's J6 at 0.48 rad/m,
    # beyond what a model file accepts).
    for j in range(robot.n_joints):
        lam = min(deflection / tau[j], 10.0 * typical) if carried[j] else typical
        x[L.index(f"joint{j + 1}.lambda")] = lam * np.exp(rng.uniform(-0.4, 0.4))
    x[model.base_index[0]] = (
        base
        if base is not None
        else np.array([2.0, -0.4, -0.2, np.radians(160.0), 0.01, -0.02])
    )
    _apply_extras(model, x, extras, rng)
    return TrueRobot(
        model,
        x,
        0.02 if "thermal" in extras else 0.0,
        tuple(extras),
        f"{robot.name}: random tolerances (seed {seed}), gravity compliance from "
        + ("the lumped self-weight layout" if lumped else "the link masses")
        + (f" + {', '.join(extras)}" if extras else ""),
        info={"seed": seed},
    )


def robot_experiment(
    truth: TrueRobot,
    seed: int = 0,
    *,
    n_train: int = 60,
    n_test: int = 300,
    q_train: Float | None = None,
    tracker: LaserTracker | None = None,
    new_session: bool = False,
) -> Experiment:
    """A laser-tracker calibration of ``truth``: ``q_train`` (a plan's poses) or
    ``n_train`` random poses to calibrate, ``n_test`` random poses to test
    (``new_session``: measured from a second tracker station, 0.6 m and 25 deg away, so
    the test set has a user frame of its own)."""
    rng = np.random.default_rng(seed + 1)
    robot = truth.robot
    tracker = tracker or LaserTracker()
    if q_train is None:
        q = random_joint_poses(robot, n_train + n_test, rng)
        n_train_ = n_train
    else:
        q_train = np.asarray(q_train, np.float64)
        q = np.concatenate([q_train, random_joint_poses(robot, n_test, rng)])
        n_train_ = q_train.shape[0]
    p_true, _ = truth.evaluate(q, sequence=np.arange(q.shape[0]))
    if q_train is None:
        tr, te = _split(q.shape[0], n_train_, rng)
    else:
        tr, te = np.arange(n_train_), np.arange(n_train_, q.shape[0])
    if new_session:  # the second station sees the test poses in its own frame
        c, s_ = np.cos(np.radians(25.0)), np.sin(np.radians(25.0))
        R = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        p_true[te] = p_true[te] @ R.T + np.array([0.3, -0.5, 0.05])
    p_meas, sigma = tracker.measure(p_true, rng)
    payload = (
        np.full(q.shape[0], robot.payload_kg) if robot.payload_kg is not None else None
    )
    meas = Measurements(
        "point",
        q,
        p_meas,
        sigma=sigma,
        payload_kg=payload,
        rows=np.arange(1, q.shape[0] + 1),
        source=f"{robot.name} twin (simulated)",
    )
    return Experiment(
        f"{robot.name} twin: laser tracker",
        truth,
        meas.subset(tr),
        meas.subset(te),
        PlannedPoses(q, np.zeros(q.shape[0], np.intp), q.shape[0]),
        info={
            "seed": seed,
            "robot": robot.name,
            "n_poses": int(q.shape[0]),
            "tracker_um": [tracker.sigma0 * 1e6, tracker.per_m * 1e6],
            "test_session": "new" if new_session else "same",
        },
    )
