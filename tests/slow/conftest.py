"""A sensor calibrated from simulated images, shared by the slow sensor tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from kinecal.sensor import (
    ChessboardTarget,
    Sensor,
    board_pose,
    calibrate_camera,
    calibrate_planes,
    paper_sensor,
    simulate_calibration,
)


@dataclass(frozen=True)
class CalibratedSensor:
    true: Sensor  # what renders the images
    calibrated: Sensor  # what Zhang's method and the plane fit made of them


@pytest.fixture(scope="session")
def calibrated_sensor() -> CalibratedSensor:
    """Camera by Zhang's method from 15 chessboard views, light planes from stripes on
    the board at 5 poses, all rendered at full resolution from the paper's sensor."""
    true = paper_sensor()
    rng = np.random.default_rng(2024)
    tgt = ChessboardTarget()
    ses = simulate_calibration(true, rng, n_views=15, n_plane_poses=5)
    cc = calibrate_camera(ses.chessboard_images, tgt)
    poses = [board_pose(im, cc.camera, tgt) for im in ses.plane_board_images]
    pc = calibrate_planes(cc.camera, poses, ses.plane_stripe_images)
    return CalibratedSensor(true, Sensor(cc.camera, pc.planes))
