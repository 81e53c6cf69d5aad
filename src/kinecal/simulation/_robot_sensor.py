"""A 3D-sensor calibration of a twin of any robot (``kinecal simulate --robot --sensor``).

The paper's experiment 1 (Sec. 5.2) on a robot other than the LR Mate 200iD: a 3D sensor
on the flange sees four ceramic spheres fixed on a plate (the user frame) from all around
their upper halves at the sensor's 115-135 mm working distance.

* The sensor's cam frame is the robot's tool (``--tool``); a robot without one gets
  :data:`SENSOR_MOUNT_MM` (a sensor beside the flange, looking along the flange's z). The
  true mount is off that by about 1 mm and 0.3 deg (a CAD mount, never exact).
* The spheres are placed where this robot can look at them from above: centres seen from
  random poses within the joint limits with the sensor looking down, within 60 deg of the
  base's x axis, at middling reach, spread by farthest-point sampling.
* The views are planned by inverse kinematics on the nominal robot (the user's model),
  each started from the nearest of a bank of random poses, so any arm (UR, 7 axes, a
  prismatic joint) finds them; the true robot then goes wherever those angles take it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinecal.errors import ConfigError
from kinecal.geometry import euler_transform, matrix_to_euler_zyx, rot_z
from kinecal.measurement import Measurements
from kinecal.models import ModelInputs, solve_ik
from kinecal.robot import RobotDescription
from kinecal.simulation._experiments import Experiment, _split, planning_model
from kinecal.simulation._instruments import SphereSensor
from kinecal.simulation._planning import PlannedPoses, _wrap_turns
from kinecal.simulation._robot_twin import random_joint_poses, robot_truth
from kinecal.simulation._truth import TrueRobot
from kinecal.typing import Float

__all__ = [
    "SENSOR_MOUNT_MM",
    "robot_sensor_experiment",
    "robot_sensor_truth",
    "robot_sensor_twin",
    "sensor_robot",
]

# The default cam frame in the flange frame [mm]: beside the flange, looking along its z.
SENSOR_MOUNT_MM = (35.0, 0.0, 75.0)
_SPHERE_RADIUS = 15e-3  # [m], the paper's ceramic spheres (Table 2)
_STANDOFF = (0.115, 0.135)  # [m], the sensor's working distance
_BANK = 4000  # random poses to seed the inverse kinematics from
_MOUNT_TOL = (1e-3, np.radians(0.3))  # the true mount's deviation from CAD [m, rad]


def sensor_robot(robot: RobotDescription) -> RobotDescription:
    """``robot`` carrying the sensor: its tool is the cam frame; a robot without a tool
    (identity) gets :data:`SENSOR_MOUNT_MM`."""
    if not np.allclose(robot.T_flange_tool, np.eye(4)):
        return robot
    mount = np.array([*SENSOR_MOUNT_MM, 0.0, 0.0, 0.0]) * ([1e-3] * 3 + [1.0] * 3)
    return replace(robot, T_flange_tool=euler_transform(mount))


def _bank(
    robot: RobotDescription, rng: np.random.Generator
) -> tuple[Float, Float, Float]:
    """Random poses within the limits and their nominal cam frames in the base frame:
    q (B, n), p (B, 3), R (B, 3, 3)."""
    from kinecal.models import CalibrationModel, ModelSpec

    model = CalibrationModel(robot, ModelSpec.preset("kinematic"))
    q = random_joint_poses(robot, _BANK, rng)
    out = model.evaluate(model.nominal, ModelInputs.make(q), orientation=True)
    assert out.R_user_cam is not None
    # The nominal model's user frame is the robot base (identity base frame).
    return q, out.p_user, out.R_user_cam


def _sphere_sites(
    robot: RobotDescription, rng: np.random.Generator, n: int = 4
) -> Float:
    """``n`` sphere centres (n, 3) in the robot base frame [m] the sensor can see from
    above: see the module docstring."""
    _, p, R = _bank(robot, rng)
    up = -robot.gravity / np.linalg.norm(robot.gravity)
    z = R[:, :, 2]
    c = p + z * np.mean(_STANDOFF)
    down = z @ up < -np.cos(np.radians(30.0))
    radial = c - np.outer(c @ up, up)
    r = np.linalg.norm(radial, axis=1)
    ok = down & (r > 1e-3)
    if ok.sum() < n:
        raise ConfigError(
            f"{robot.name}: the sensor looks down from too few poses within the joint "
            "limits to place the spheres; expected an arm that can point its tool "
            "(--tool) down."
        )
    lo, hi = np.quantile(r[ok], [0.35, 0.75])
    h = c @ up
    mid = np.median(h[ok & (r >= lo) & (r <= hi)])
    level = ok & (r >= lo) & (r <= hi) & (np.abs(h - mid) < 0.1 * hi)  # on a plate
    front = radial @ _front(up) > np.cos(np.radians(60.0)) * r
    pick = level & front
    if pick.sum() < n:
        pick = level if level.sum() >= n else ok
    cand = c[pick]
    # Farthest-point sampling from the candidate nearest their median.
    chosen = [int(np.argmin(np.linalg.norm(cand - np.median(cand, axis=0), axis=1)))]
    d = np.linalg.norm(cand - cand[chosen[0]], axis=1)
    for _ in range(n - 1):
        chosen.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(cand - cand[chosen[-1]], axis=1))
    return cand[chosen]


def _front(up: Float) -> Float:
    """The base's x axis made level (the robot's front)."""
    x = np.array([1.0, 0.0, 0.0]) - up[0] * up
    if np.linalg.norm(x) < 1e-6:  # gravity along x: the base's y
        x = np.array([0.0, 1.0, 0.0]) - up[1] * up
    return x / np.linalg.norm(x)


def _plate_frame(centres: Float, up: Float) -> Float:
    """The robot base in the plate (user) frame, (6,) [m, rad]: the plate's origin under
    the spheres' centroid, turned 20 deg and tilted slightly against the base."""
    T_user_base = euler_transform([0.0, 0.0, 0.0, np.radians(20.0), 0.004, -0.006])
    mid = centres.mean(axis=0)
    T_user_base[:3, 3] = -T_user_base[:3, :3] @ (mid - 0.05 * up)
    out = np.zeros(6)
    out[:3] = T_user_base[:3, 3]
    out[3:] = matrix_to_euler_zyx(T_user_base[:3, :3])
    return out


def robot_sensor_truth(
    robot: RobotDescription, *, seed: int = 0, extras: tuple[str, ...] = ()
) -> tuple[TrueRobot, Float]:
    """A true robot (:func:`robot_truth`) carrying the sensor, with the plate of spheres
    as its user frame; returns it and the sphere centres in the user frame (4, 3) [m]."""
    robot = sensor_robot(robot)
    rng = np.random.default_rng(seed + 2)
    centres = _sphere_sites(robot, rng)
    base = _plate_frame(centres, -robot.gravity / np.linalg.norm(robot.gravity))
    truth = robot_truth(robot, seed=seed, base=base, extras=extras)
    x = truth.params.copy()
    dev = np.concatenate(
        [rng.normal(size=3) * _MOUNT_TOL[0], rng.normal(size=3) * _MOUNT_TOL[1]]
    )
    x[truth.model.cam_index[0]] += dev
    R_b, t_b = euler_transform(base)[:3, :3], base[:3]
    spheres = centres @ R_b.T + t_b
    truth = replace(
        truth,
        params=x,
        description=truth.description + ", a 3D sensor and four spheres",
    )
    return truth, spheres


def _views(
    truth: TrueRobot,
    spheres: Float,
    per_sphere: int,
    rng: np.random.Generator,
    *,
    min_elevation_deg: float = 25.0,
    max_attempts: int = 10,
) -> PlannedPoses:
    """Up to ``per_sphere`` poses looking at each sphere (the experiment-1 layout),
    planned on the nominal robot with the set-up's frames."""
    pm, x = planning_model(truth)
    robot = truth.robot
    q_bank, p_bank, R_bank = _bank(robot, rng)
    R_b, t_b = pm.base_frames(x)
    p_bank = p_bank @ R_b[0].T + t_b[0]  # to the user frame (seeds: the nominal cam)
    R_bank = R_b[0] @ R_bank
    up = R_b[0] @ (-robot.gravity / np.linalg.norm(robot.gravity))
    lim = robot.limits.copy()
    lim[:, 0] += np.radians(2.0)
    lim[:, 1] -= np.radians(2.0)
    sin_lo = np.sin(np.radians(min_elevation_deg))
    qs, labels = [], []
    for k, c in enumerate(spheres):
        got: list[Float] = []
        n_got = 0
        for _ in range(max_attempts):
            m = 4 * per_sphere
            p_t, R_t = _view_targets(c, up, m, sin_lo, rng)
            seed = _nearest(p_bank, R_bank, q_bank, p_t, R_t)
            res = solve_ik(pm, x, p_t, seed, R_target=R_t, limits=lim, max_iter=60)
            ok = np.flatnonzero(res.converged)
            got.append(_wrap_turns(res.q_ctrl[ok], lim))
            n_got += ok.size
            if n_got >= per_sphere:
                break
        q = np.concatenate(got)[:per_sphere]
        qs.append(q)
        labels.append(np.full(q.shape[0], k))
    return PlannedPoses(
        np.concatenate(qs), np.concatenate(labels), per_sphere * spheres.shape[0]
    )


def _view_targets(
    c: Float, up: Float, m: int, sin_lo: float, rng: np.random.Generator
) -> tuple[Float, Float]:
    """``m`` cam frames (positions (m, 3), orientations (m, 3, 3)) looking at ``c`` from
    above ``asin(sin_lo)`` elevation at the working distance, turned at random about the
    optical axis."""
    # An orthonormal frame with ``up`` as its z.
    e1 = np.cross(up, [1.0, 0.0, 0.0])
    if np.linalg.norm(e1) < 0.1:
        e1 = np.cross(up, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    s = rng.uniform(sin_lo, 1.0, m)  # uniform on the spherical cap
    az = rng.uniform(-np.pi, np.pi, m)
    h = np.sqrt(1.0 - s * s)
    v = np.outer(h * np.cos(az), e1) + np.outer(h * np.sin(az), e2) + np.outer(s, up)
    p = c + v * rng.uniform(*_STANDOFF, m)[:, None]
    z = -v
    x0 = np.cross(z, up)
    x0 /= np.linalg.norm(x0, axis=1, keepdims=True)
    y0 = np.cross(z, x0)
    R = np.stack([x0, y0, z], axis=2) @ rot_z(rng.uniform(-np.pi, np.pi, m))
    return p, R


def _nearest(p_bank: Float, R_bank: Float, q_bank: Float, p: Float, R: Float) -> Float:
    """The bank pose nearest each target frame (0.1 m of position weighs as 1 rad)."""
    dp = np.linalg.norm(p[:, None, :] - p_bank[None, :, :], axis=2) / 0.1
    tr = np.einsum("mij,bij->mb", R, R_bank)
    ang = np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))
    return q_bank[np.argmin(dp + ang, axis=1)]


def robot_sensor_experiment(
    truth: TrueRobot,
    spheres: Float,
    seed: int = 0,
    *,
    n_train: int = 100,
    n_test: int = 300,
    sensor: SphereSensor | None = None,
) -> Experiment:
    """A 3D-sensor calibration of ``truth`` (from :func:`robot_sensor_truth`): views of
    the spheres ``spheres`` (4, 3) [m, user frame], ``n_train`` to calibrate and
    ``n_test`` to test (at most, as many as the planning reaches)."""
    rng = np.random.default_rng(seed + 1)
    sensor = sensor or SphereSensor()
    n_s = spheres.shape[0]
    plan = _views(truth, spheres, -(-(n_train + n_test) // n_s), rng)
    q, ti = plan.q_ctrl, plan.label
    p0, R = truth.evaluate(q, orientation=True)
    assert R is not None
    p_cam = sensor.measure(np.einsum("nji,nj->ni", R, spheres[ti] - p0), rng)
    labels = tuple(f"S{k + 1}" for k in range(n_s))
    robot = truth.robot
    payload = (
        np.full(q.shape[0], robot.payload_kg) if robot.payload_kg is not None else None
    )
    meas = Measurements(
        "sensor",
        q,
        p_cam,
        target_index=ti,
        targets=spheres,
        target_labels=labels,
        payload_kg=payload,
        rows=np.arange(1, q.shape[0] + 1),
        source=f"{robot.name} twin (simulated)",
    )
    tr, te = _split(q.shape[0], min(n_train, q.shape[0] - 1), rng)
    te = te[:n_test]
    return Experiment(
        f"{robot.name} twin: 3D sensor and spheres",
        truth,
        meas.subset(tr),
        meas.subset(te),
        plan,
        targets=(labels, spheres, np.full(n_s, _SPHERE_RADIUS)),
        info={
            "seed": seed,
            "robot": robot.name,
            "n_poses": int(q.shape[0]),
            "sensor_um": [sensor.sigma_xy * 1e6, sensor.sigma_z * 1e6],
        },
    )


def robot_sensor_twin(
    robot: RobotDescription,
    seed: int = 0,
    *,
    n_train: int = 100,
    n_test: int = 300,
    extras: tuple[str, ...] = (),
    noise_um: float | None = None,
) -> Experiment:
    """:func:`robot_sensor_truth` measured by :func:`robot_sensor_experiment`;
    ``noise_um`` the sensor's noise across its optical axis (twice that along it;
    default the paper's sensor, 4 and 8 um)."""
    truth, spheres = robot_sensor_truth(robot, seed=seed, extras=extras)
    sensor = (
        SphereSensor(noise_um * 1e-6, 2 * noise_um * 1e-6)
        if noise_um is not None
        else None
    )
    return robot_sensor_experiment(
        truth, spheres, seed, n_train=n_train, n_test=n_test, sensor=sensor
    )
