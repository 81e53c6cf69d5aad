"""Issue 31: the default (``--model auto``) against the best fixed model on a matrix of
twins: four robots (a UR-type arm, a generic 6R arm, the 7-axis FR3, the long-arm LR
Mate) x four truths (geometry only; with gravity deflection; with transmission errors;
both), calibrated on 150 poses from one end of the workspace and scored on 800 from the
other with the tracker moved and user and tool frames refitted (a new session in
another region). Over this matrix and a second one at 40 poses, random splits and two
seeds (128 cases, docs/theory.md), the default was within 1.05x of the best fixed model
in all but two: 40 poses of a 6R arm whose truth has transmission errors and no gravity
deflection, where `ntm` was chosen and `full` extrapolated better (1.14x, 1.26x)."""

from __future__ import annotations

import pytest

from kinecal.identification import calibrate, evaluate
from tests.identification.test_issue_31_transfer import (
    auto_calibration,
    robot_new_region,
)

TRUTHS = {
    "geometry": {"ntm_amplitude": 0.0, "deflection": 1e-9},
    "gravity": {"ntm_amplitude": 0.0},
    "transmission": {"deflection": 1e-9},
    "both": {},
}


@pytest.mark.slow
@pytest.mark.parametrize("truth_kind", sorted(TRUTHS))
@pytest.mark.parametrize(
    "name", ["ur5e", "generic-6r", "franka-fr3", "fanuc-lrmate200id-7l"]
)
def test_default_within_5_percent_of_the_best_fixed_model_in_a_new_region(
    name, truth_kind
):
    robot, train, test = robot_new_region(name, 0, **TRUTHS[truth_kind])
    refit = ("user", "tool")
    fixed = {
        m: evaluate(
            calibrate(robot, train, m).calibrated, test, refit=refit
        ).metrics.rms_mm
        for m in ("kinematic", "ntm", "rfcm", "full")
    }
    res = auto_calibration(robot, train)
    got = evaluate(res.calibrated, test, refit=refit).metrics.rms_mm
    assert got <= 1.05 * min(fixed.values()), (res.model.spec.name, got, fixed)
