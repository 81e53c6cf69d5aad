"""Issue 31's UR10 report as a twin (benchmarks/_issue31_rules.py, ``ur10_sessions``):
self-weight compliance and small transmission errors, 400 poses of one half of the
workspace, three later sessions with other pose distributions after the tracker moved
and the tool was re-mounted (user and tool frames refitted). The default (``--model
auto``) within 1.05x of the best fixed model on every new session; before a series cut
below reproducible Fourier orders was barred, "full order 1" was chosen in seeds 2 and 3
(up to 1.17x)."""

from __future__ import annotations

import pytest
from benchmarks._issue31_rules import REFIT, ur10_sessions

from kinecal.identification import CalibrationOptions, calibrate, evaluate, select_model


@pytest.mark.slow
@pytest.mark.parametrize(("seed", "vary"), [(s, False) for s in range(6)] + [(2, True)])
def test_default_within_5_percent_on_every_new_session_of_the_ur10_twin(seed, vary):
    robot, train, sessions = ur10_sessions(seed, vary)
    sel = select_model(robot, train)
    opts = CalibrationOptions().tuned(prior_scale=sel.prior_scale)
    auto = (sel.calibration(opts) or calibrate(robot, train, sel.spec, opts)).calibrated
    fixed = [
        calibrate(robot, train, m).calibrated
        for m in ("kinematic", "ntm", "rfcm", "full")
    ]
    for test in sessions:
        best = min(evaluate(c, test, refit=REFIT).metrics.rms_mm for c in fixed)
        got = evaluate(auto, test, refit=REFIT).metrics.rms_mm
        assert got <= 1.05 * best, (sel.spec.name, got, best)
