"""Compensation benchmarks (issue 23): speed on 10,000 targets and the accuracy the true
robot reaches on the tracker twin, the stretched elbow of the LR Mate included.

The twin: the paper's experiment-2 robot (Tables 6-7) measured by an API T3-class laser
tracker (15 um + 6 um/m, 2 sigma) at 500 random poses over a joint box that holds the
stretched elbow (J2 + J3 = 84 deg), calibrated with the full model. The targets: 500 tool
points of the true robot (150 of them within 3 deg of the stretched elbow), with program
joints 0.2 deg off the truth.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

BOX_DEG = np.array(
    [[-60, 60], [-20, 70], [-60, 60], [-180, 180], [-110, 110], [-180, 180]], float
)
STRETCHED_DEG = float(np.degrees(np.arctan2(335.0, 35.0)))


def _box(rng: np.random.Generator, n: int) -> np.ndarray:
    lo, hi = np.radians(BOX_DEG).T
    return rng.uniform(lo, hi, (n, 6))


def _stretched(rng: np.random.Generator, n: int) -> np.ndarray:
    q = _box(rng, n)
    q[:, 1] = np.radians(rng.uniform(30.0, 65.0, n))
    q[:, 2] = np.radians(STRETCHED_DEG + rng.uniform(-3.0, 3.0, n)) - q[:, 1]
    return q


def compensation_cases(
    record: Callable[..., None],
    repeat: int,
    median_time: Callable[[Callable[[], Any], int], tuple[float, Any]],
) -> None:
    """Record the compensation cases with ``record(name, seconds, target, **extra)``."""
    from kinecal.compensation import compensate
    from kinecal.identification import Measurements, calibrate
    from kinecal.simulation import LaserTracker, paper_truth

    rng = np.random.default_rng(23)
    truth = paper_truth(2, seed=23)
    q = _box(rng, 500)
    p_true, _ = truth.evaluate(q)
    p_meas, sigma = LaserTracker().measure(p_true, rng)
    train = Measurements("point", q, p_meas, sigma=sigma, source="tracker twin")
    cal = calibrate(truth.robot, train, "full").calibrated

    goal = np.concatenate([_stretched(rng, 150), _box(rng, 350)])
    p_t, _ = truth.evaluate(goal)
    seed = goal + np.radians(0.2) * rng.standard_normal(goal.shape)
    t, out = median_time(lambda: compensate(cal, p_t, seed), repeat)
    err = np.linalg.norm(truth.evaluate(out.q_ctrl)[0] - p_t, axis=1) * 1e3
    record(
        "compensate_twin_500_stretched_elbow",
        t,
        "every target; true robot <= 0.015 mm RMS, <= 0.05 mm max",
        ok=int(out.ok.sum()),
        achieved_rms_mm=float(np.sqrt(np.mean(err**2))),
        achieved_max_mm=float(err.max()),
        achieved_stretched_rms_mm=float(np.sqrt(np.mean(err[:150] ** 2))),
        predicted_max_mm=float(out.error.max() * 1e3),
        max_joint_change_deg=float(np.degrees(np.abs(out.joint_change)).max()),
        iterations=int(out.iterations),
    )

    goal = _box(rng, 10_000)
    p_t, _ = truth.evaluate(goal)
    seed = goal + np.radians(0.2) * rng.standard_normal(goal.shape)
    t, out = median_time(lambda: compensate(cal, p_t, seed), repeat)
    record(
        "compensate_twin_10000",
        t,
        "~0.1-0.2 s",
        ok=int(out.ok.sum()),
        per_target_us=float(t / 10_000 * 1e6),
    )
