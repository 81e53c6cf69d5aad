"""The per-pose errors of residuals.csv and report.html from the fit's own evaluations
(issue 36): no forward pass at the registered point or at the solution when the
result's workspace holds them, and the same numbers to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

import kinecal.measurement as measurement
from kinecal.identification import calibrate
from kinecal.report import pose_errors
from kinecal.simulation import LaserTracker, experiment2


@pytest.fixture(scope="module")
def fitted():
    twin = experiment2(31, tracker=LaserTracker(5e-6, 0.0), n_side=5)
    return calibrate(twin.truth.robot, twin.train, "full"), twin.train


def _fields(p):
    return [p.row, p.q, p.p_mm, p.before_mm, p.after_mm]


def test_pose_errors_take_no_pass_and_equal_fresh_ones(fitted, monkeypatch):
    result, meas = fitted
    assert result.workspace is not None and result.workspace.meas is meas
    calls = []
    fresh = measurement.residuals

    def counted(*a, **k):
        calls.append(1)
        return fresh(*a, **k)

    monkeypatch.setattr(measurement, "residuals", counted)
    cached = pose_errors(result, meas)
    assert not calls  # both from the fit's cache
    monkeypatch.setattr(result, "workspace", None)
    again = pose_errors(result, meas)
    assert len(calls) == 2  # without the cache: a pass each
    for a, b in zip(_fields(cached), _fields(again)):
        assert a.tobytes() == b.tobytes()


def test_other_rows_are_evaluated_afresh(fitted):
    result, meas = fitted
    part = meas.subset(np.arange(meas.n // 2))
    errors = pose_errors(result, part)
    assert errors.n == part.n and np.isfinite(errors.after_mm).all()
