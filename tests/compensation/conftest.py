"""The tracker twin of issue 23: the paper's experiment-2 robot (Tables 6-7) measured by
an API T3-class laser tracker at random poses over a joint box that holds the stretched
elbow of the LR Mate (J2 + J3 = 84 deg), calibrated with the full model."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from kinecal.identification import CalibratedModel, Measurements, calibrate
from kinecal.simulation import LaserTracker, TrueRobot, paper_truth

# Joint box of the calibration poses and the targets [deg]: J2 and J3 reach the
# stretched elbow; the wrist turns widely.
BOX_DEG = np.array(
    [[-60, 60], [-20, 70], [-60, 60], [-180, 180], [-110, 110], [-180, 180]], float
)
# theta3 - (-90 deg) ... the stretched elbow of the LR Mate: the forearm (a3 = 35 mm,
# d4 = -335 mm) in line with the upper arm when J2 + J3 = atan2(335, 35) = 84.04 deg.
STRETCHED_DEG = float(np.degrees(np.arctan2(335.0, 35.0)))


@dataclass
class Twin:
    truth: TrueRobot
    calibrated: CalibratedModel
    train: Measurements


def box_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    lo, hi = np.radians(BOX_DEG).T
    return rng.uniform(lo, hi, (n, 6))


def stretched_poses(rng: np.random.Generator, n: int) -> np.ndarray:
    """Poses within 3 deg of the stretched elbow, inside the box."""
    q = box_poses(rng, n)
    q[:, 1] = np.radians(rng.uniform(30.0, 65.0, n))
    q[:, 2] = np.radians(STRETCHED_DEG + rng.uniform(-3.0, 3.0, n)) - q[:, 1]
    return q


def write_targets_csv(path: Path, p: np.ndarray, q: np.ndarray) -> Path:
    """A TARGETS.csv of a 6-joint arm: tool points ``p`` (N, 3) [m] and seed joints
    ``q`` (N, 6) [rad], in mm and deg."""
    head = "x_mm,y_mm,z_mm," + ",".join(f"j{k}_deg" for k in range(1, 7))
    lines = [head]
    for pi, qi in zip(p * 1e3, np.degrees(q)):
        lines.append(",".join(f"{v:.6f}" for v in (*pi, *qi)))
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="session")
def tracker_twin() -> Twin:
    rng = np.random.default_rng(23)
    truth = paper_truth(2, seed=23)
    q = box_poses(rng, 500)
    p_true, _ = truth.evaluate(q)
    p_meas, sigma = LaserTracker().measure(p_true, rng)
    train = Measurements(
        "point",
        q,
        p_meas,
        sigma=sigma,
        rows=np.arange(1, q.shape[0] + 1),
        source="tracker twin (issue 23)",
    )
    res = calibrate(truth.robot, train, "full")
    assert res.success
    return Twin(truth, res.calibrated, train)


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


@pytest.fixture(scope="module")
def model_file(tracker_twin, tmp_path_factory):
    """The tracker twin's calibration as a model.yaml (one per test module)."""
    from kinecal.io import save_model

    return save_model(
        tmp_path_factory.mktemp("model") / "model.yaml", tracker_twin.calibrated
    )
