"""Rows of 0 kg (no payload) beside rows with a payload.

A payload study measures the same poses with and without the payload. ``payload_kg`` 0
was refused ("a positive mass"), so such data could not be calibrated at all. Now a 0 kg
row has no load torque (load scale 0) and the reference payload is the median of the rows
with one. A column that is 0 in every row cannot calibrate a payload compliance and is
refused by name for such a model (the fit would start at a saddle: both the compliance
and the link moments at zero).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.demo import truth_model
from kinecal.errors import DataError
from kinecal.identification import calibrate
from kinecal.io import read_measurements
from kinecal.measurement import Measurements
from kinecal.robot import load_robot
from kinecal.workflows import simulate_robot_twin


@pytest.fixture(scope="module")
def twin():
    robot = replace(load_robot("ur10e"), payload_kg=8.0)
    sim = simulate_robot_twin(robot, n_train=150, n_test=120, seed=3)
    return sim.experiment, truth_model(sim.experiment)


def _without_payload(truth, m: Measurements, every: int) -> Measurements:
    """``m`` with every ``every``-th row measured without its payload (the truth's
    own deflection difference applied to the measured point)."""
    zero = np.arange(m.n) % every == 0
    m0 = replace(m, payload_kg=np.where(zero, 0.0, m.payload_kg))
    shift = truth.predict(m0).raw_position - truth.predict(m).raw_position
    out = replace(m0, p=m.p + shift)  # residuals are model minus measured
    assert np.allclose(truth.predict(out).raw_position, truth.predict(m).raw_position)
    return out


def test_mixed_payload_rows_calibrate_to_the_truth(twin):
    exp, truth = twin
    train = _without_payload(truth, exp.train, 2)
    test = _without_payload(truth, exp.test, 2)
    # The payload moves the tool by a visible amount, else the test shows nothing.
    moved = test.p - exp.test.p
    assert np.abs(moved).max() > 0.1e-3
    res = calibrate(exp.truth.robot, train, "full")
    assert res.calibrated.reference_payload_kg == pytest.approx(8.0)
    cal = res.calibrated.metrics(test).rms_mm
    ideal = truth.metrics(test).rms_mm
    assert cal < 1.15 * ideal, (cal, ideal)
    # Scoring 0 kg rows as if they carried the payload is far worse: the zeros are used.
    loaded = replace(test, payload_kg=np.full(test.n, 8.0))
    assert res.calibrated.metrics(loaded).rms_mm > 2.0 * cal


def test_all_zero_payload_column_is_refused_for_a_payload_model(twin):
    exp, truth = twin
    train = _without_payload(truth, exp.train, 1)
    with pytest.raises(DataError, match="'payload_kg' is 0 in every row"):
        calibrate(exp.truth.robot, train, "full")
    # A model without payload compliance takes it; a model with one scores it.
    calibrate(exp.truth.robot, train, "kinematic")
    assert truth.metrics(train).rms_mm < 0.05


def test_csv_takes_zero_and_names_a_negative_payload(tmp_path):
    robot = load_robot("ur10e")
    head = "j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,x_mm,y_mm,z_mm,payload_kg\n"
    rows = [
        f"{10 * i},{-80 + 9 * i},{70 - 8 * i},{-60 + 11 * i},{90 - 7 * i},{5 * i},"
        f"{900 + i},{-200 + 3 * i},{400 + 2 * i}"
        for i in range(8)
    ]
    ok = tmp_path / "ok.csv"
    ok.write_text(
        head + "".join(f"{r},{0 if i % 2 else 5}\n" for i, r in enumerate(rows))
    )
    meas = read_measurements(ok, robot)
    assert meas.payload_kg is not None and meas.reference_payload() == 5.0
    assert np.array_equal(meas.model_inputs(5.0).load_scale[:2], [1.0, 0.0])
    bad = tmp_path / "bad.csv"
    bad.write_text(
        head + "".join(f"{r},{-1 if i == 3 else 5}\n" for i, r in enumerate(rows))
    )
    with pytest.raises(
        DataError,
        match=r"line 5, column 'payload_kg': -1; expected a mass in kg, 0 or more",
    ):
        read_measurements(bad, robot)
