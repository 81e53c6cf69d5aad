"""Simulated data sets shared by the identification tests (module-scoped: built once)."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.simulation import LaserTracker, experiment1, experiment2

NOISE = 5e-6  # per-axis tracker noise of issue 4 [m]
FLOOR_MM = NOISE * np.sqrt(3) * 1e3  # RMS of a 3-D error norm at that noise


@pytest.fixture(scope="session")
def exp2_exact():
    """Experiment 2 (100 train / ~6900 test), truth drawn from the full model."""
    return experiment2(11, tracker=LaserTracker(NOISE, 0.0))


@pytest.fixture(scope="session")
def exp2_extras():
    """Experiment 2 with effects outside every model."""
    return experiment2(
        12, tracker=LaserTracker(NOISE, 0.0), extras=("harmonics", "wrist", "masses")
    )


@pytest.fixture(scope="session")
def exp1_exact():
    return experiment1(13)
