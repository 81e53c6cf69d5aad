"""A sensor calibrated from simulated images, shared by the slow sensor tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from kinecal.sensor import (
    ChessboardTarget,
    Sensor,
    SensorCalibration,
    calibrate_sensor,
    paper_sensor,
    simulate_calibration,
)


@dataclass(frozen=True)
class CalibratedSensor:
    true: Sensor  # what renders the images
    calibrated: Sensor  # what the joint adjustment made of them
    result: SensorCalibration


@pytest.fixture(scope="session")
def calibrated_sensor() -> CalibratedSensor:
    """Camera, target poses and the 120 light planes in one bundle adjustment, from 25
    chessboard views and the target at 5 poses, all rendered at full resolution from
    the paper's sensor (images rendered when read, pose by pose)."""
    true = paper_sensor()
    rng = np.random.default_rng(2024)
    tgt = ChessboardTarget()
    ses = simulate_calibration(true, rng, n_views=25, n_plane_poses=5)
    res = calibrate_sensor(
        ses.chessboard_images, tgt, ses.plane_board_images, ses.plane_stripe_images
    )
    return CalibratedSensor(true, res.sensor, res)
