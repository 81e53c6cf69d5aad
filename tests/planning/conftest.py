"""Shared data of the planning tests: the experiment-2 twin and its planning set-up."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from kinecal.identification import Measurements
from kinecal.models import CalibrationModel
from kinecal.planning import Instrument, planning_model
from kinecal.simulation import LaserTracker, experiment2
from kinecal.simulation import planning_model as twin_planning_model

NOISE = 5e-6  # per-axis tracker noise [m], as the issue-4 tests
FLOOR_MM = NOISE * np.sqrt(3) * 1e3  # RMS of the 3-D error norm of that noise


@dataclass
class Twin:
    """All ~7000 poses of experiment 2 as one candidate set, with what the user knows."""

    meas: Measurements  # every pose, measured (rows in planning order)
    robot: object
    model: CalibrationModel  # the 'full' model for tracker data
    params: np.ndarray  # nominal joints, the set-up's frames


def twin_for(seed: int) -> Twin:
    e = experiment2(seed, tracker=LaserTracker(NOISE, 0.0))
    both = np.concatenate([e.train.rows, e.test.rows])
    order = np.argsort(both)
    q = np.concatenate([e.train.q_ctrl, e.test.q_ctrl])[order]
    p = np.concatenate([e.train.p, e.test.p])[order]
    sigma = np.concatenate([e.train.sigma, e.test.sigma])[order]
    meas = Measurements(
        "point", q, p, sigma=sigma, rows=np.arange(1, q.shape[0] + 1), source="twin"
    )
    # What the user plans with: nominal joints, the tracker set-up's frames.
    pm, x = twin_planning_model(e.truth)
    cm, params = planning_model(e.truth.robot, "full", Instrument("tracker", NOISE))
    params[cm.base_index[0]] = x[pm.base_index[0]]
    params[cm.cam_index[0]] = x[pm.cam_index[0][:3]]
    return Twin(meas, e.truth.robot, cm, params)


@pytest.fixture(scope="session")
def twin() -> Twin:
    return twin_for(0)
