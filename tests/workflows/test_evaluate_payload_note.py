"""``evaluate`` of data without a ``payload_kg`` column on a model calibrated with a
payload: the poses are scored at the calibration's reference payload, which the console
now says (it was silent); a model whose predictions do not depend on the payload says
nothing."""

from __future__ import annotations

from dataclasses import replace

import pytest

from kinecal.identification import calibrate
from kinecal.robot import load_robot
from kinecal.workflows import simulate_robot_twin
from kinecal.workflows._evaluate import evaluate_measurements


@pytest.fixture(scope="module")
def twin():
    robot = replace(load_robot("ur10e"), payload_kg=8.0)
    return simulate_robot_twin(robot, n_train=60, n_test=20, seed=5).experiment


def _notes(ev) -> list[str]:
    return [ln for ln in ev.messages if "payload_kg" in ln]


def test_scoring_at_the_reference_payload_is_said(twin):
    cal = calibrate(twin.truth.robot, twin.train, "rfcm").calibrated
    assert cal.reference_payload_kg == pytest.approx(8.0)
    bare = replace(twin.test, payload_kg=None)
    (note,) = _notes(evaluate_measurements(cal, bare, data_name="new.csv"))
    assert note.startswith("note      new.csv: no payload_kg column")
    assert "reference payload (8 kg)" in note, note
    # With the column, or with a model that has no payload terms: nothing to say.
    assert _notes(evaluate_measurements(cal, twin.test, data_name="new.csv")) == []
    kin = calibrate(twin.truth.robot, twin.train, "kinematic").calibrated
    assert _notes(evaluate_measurements(kin, bare, data_name="new.csv")) == []
