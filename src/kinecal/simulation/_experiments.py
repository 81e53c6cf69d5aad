"""The paper's two experiments on the digital twin (Sec. 5.2, 5.3; DESIGN §8).

* :func:`experiment2`: laser tracker, seven orientations x 10^3 grid, 100 poses to
  calibrate and the rest (~6900) to test; tracker noise grows with distance.
* :func:`experiment1`: 3D sensor measuring the four ceramic spheres of Table 2 from 200
  poses (50 each), 100 to calibrate and 100 to test.

Everything random comes from one seed, so a run is reproducible to the bit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kinecal.measurement import Measurements
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.simulation._instruments import LaserTracker, SphereSensor, add_outliers
from kinecal.simulation._planning import PlannedPoses, grid_poses, sphere_poses
from kinecal.simulation._truth import TrueRobot, paper_truth
from kinecal.typing import Float

__all__ = [
    "CERAMIC_SPHERES_MM",
    "Experiment",
    "experiment1",
    "experiment2",
    "planning_model",
]

# Table 2: ceramic spheres measured by CMM (x, y, z, r in mm), frame {Ceramic} = user.
CERAMIC_SPHERES_MM = np.array(
    [
        [185.328, 408.400, 2303.870, 14.999],
        [240.396, 377.943, 2640.910, 15.002],
        [-196.154, 289.749, 2727.350, 15.001],
        [-246.181, 344.340, 2379.780, 14.998],
    ]
)


@dataclass
class Experiment:
    """A simulated calibration experiment: truth, data split and layout."""

    name: str
    truth: TrueRobot
    train: Measurements
    test: Measurements
    plan: PlannedPoses
    targets: tuple[tuple[str, ...], Float, Float] | None = None  # labels, p [m], r [m]
    outlier_rows: np.ndarray = field(default_factory=lambda: np.zeros(0, np.intp))
    info: dict[str, object] = field(default_factory=dict)


def planning_model(truth: TrueRobot) -> tuple[CalibrationModel, Float]:
    """What the user plans with: nominal joints, the set-up's frames (approximately known)."""
    pm = CalibrationModel(truth.robot, ModelSpec.preset("kinematic"))
    x = pm.layout.transfer(truth.params, truth.model.layout)
    joints = pm.layout.group_indices("joint")
    x[joints] = pm.nominal[joints]
    return pm, x


def _split(
    n: int, n_train: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    if not 0 < n_train < n:
        raise ValueError(f"n_train must be between 1 and {n - 1}; got {n_train}.")
    perm = rng.permutation(n)
    return np.sort(perm[:n_train]), np.sort(perm[n_train:])


def experiment2(
    seed: int = 0,
    *,
    n_train: int = 100,
    extras: tuple[str, ...] = (),
    tracker: LaserTracker | None = None,
    truth: TrueRobot | None = None,
    outlier_fraction: float = 0.0,
    n_side: int = 10,
) -> Experiment:
    """Experiment 2: laser tracker over seven orientations x an ``n_side``^3 grid."""
    rng = np.random.default_rng(seed)
    truth = truth or paper_truth(2, extras=extras, seed=seed)
    tracker = tracker or LaserTracker()
    pm, x = planning_model(truth)
    plan = grid_poses(pm, x, n_side=n_side)
    q = plan.q_ctrl
    order = np.arange(q.shape[0])  # measured in planning order (thermal drift)
    p_true, _ = truth.evaluate(q, sequence=order)
    p_meas, sigma = tracker.measure(p_true, rng)
    bad = np.zeros(0, np.intp)
    if outlier_fraction > 0:
        p_meas, bad = add_outliers(p_meas, rng, outlier_fraction)
    meas = Measurements(
        "point",
        q,
        p_meas,
        sigma=sigma,
        rows=np.arange(1, q.shape[0] + 1),
        source="experiment 2 (simulated)",
    )
    tr, te = _split(q.shape[0], n_train, rng)
    return Experiment(
        "experiment 2: laser tracker",
        truth,
        meas.subset(tr),
        meas.subset(te),
        plan,
        outlier_rows=bad,
        info={
            "seed": seed,
            "n_poses": int(q.shape[0]),
            "n_requested": plan.n_requested,
            "tracker_um": [tracker.sigma0 * 1e6, tracker.per_m * 1e6],
        },
    )


def experiment1(
    seed: int = 0,
    *,
    n_train: int = 100,
    extras: tuple[str, ...] = (),
    sensor: SphereSensor | None = None,
    truth: TrueRobot | None = None,
    per_sphere: int = 50,
) -> Experiment:
    """Experiment 1: the 3D sensor measuring the four ceramic spheres of Table 2."""
    rng = np.random.default_rng(seed)
    truth = truth or paper_truth(1, extras=extras, seed=seed)
    sensor = sensor or SphereSensor()
    pm, x = planning_model(truth)
    spheres = CERAMIC_SPHERES_MM[:, :3] * 1e-3
    plan = sphere_poses(pm, x, spheres, rng, per_sphere=per_sphere)
    q = plan.q_ctrl
    ti = plan.label
    # The sensor sees each sphere centre in the true cam frame.
    p0, R = truth.evaluate(q, orientation=True)
    assert R is not None
    p_cam_true = np.einsum("nji,nj->ni", R, spheres[ti] - p0)
    p_cam = sensor.measure(p_cam_true, rng)
    labels = tuple(f"S{k + 1}" for k in range(spheres.shape[0]))
    meas = Measurements(
        "sensor",
        q,
        p_cam,
        target_index=ti,
        targets=spheres,
        target_labels=labels,
        rows=np.arange(1, q.shape[0] + 1),
        source="experiment 1 (simulated)",
    )
    tr, te = _split(q.shape[0], n_train, rng)
    return Experiment(
        "experiment 1: 3D sensor and ceramic spheres",
        truth,
        meas.subset(tr),
        meas.subset(te),
        plan,
        targets=(labels, spheres, CERAMIC_SPHERES_MM[:, 3] * 1e-3),
        info={
            "seed": seed,
            "n_poses": int(q.shape[0]),
            "sensor_um": [sensor.sigma_xy * 1e6, sensor.sigma_z * 1e6],
        },
    )
