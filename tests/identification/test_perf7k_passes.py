"""Issue 36: stage 3's lifted start linearises at stage 1's solution, where stage 2
linearised (its Jacobian, with the product columns, kept from stage 1): one Jacobian pass
fewer than at stage 2's point, the same fit to the stages' tolerance; the calibration of
500 twin poses in 9 Jacobian passes (10 before), its nominal check in 1."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import calibrate, nominal_check
from kinecal.identification._calibrate import default_stages
from kinecal.identification._options import CalibrationOptions
from kinecal.identification._problem import Problem, run_stages
from kinecal.identification._stages import FullStage, TransmissionStage
from kinecal.models import pass_counts


@pytest.fixture(scope="module")
def twin500():
    from kinecal.workflows._simulate import simulate_paper_experiment

    e = simulate_paper_experiment(2, n_train=500).experiment
    return e.truth.robot, e.train


def _jacobians(fn):
    before = pass_counts()["jacobian"]
    out = fn()
    return out, pass_counts()["jacobian"] - before


def test_the_calibration_takes_nine_jacobian_passes(twin500):
    robot, meas = twin500
    res, n_fit = _jacobians(lambda: calibrate(robot, meas, "full"))
    found, n_check = _jacobians(lambda: nominal_check(res, robot, meas))
    assert res.success
    assert n_fit <= 9 and n_check <= 1
    assert not [d for d in found if d.code in ("priors_held", "nominal_mismatch")]


def _after_stage_2(robot, meas):
    stages = default_stages(CalibrationOptions())
    at = next(i for i, s in enumerate(stages) if isinstance(s, TransmissionStage))
    problem = Problem.make(robot, meas, "full")
    return problem, run_stages(problem, problem.start(), stages[: at + 1])


def test_stage_3_lifts_from_stage_1s_solution(twin500):
    robot, meas = twin500
    problem, state = _after_stage_2(robot, meas)
    assert state.linearised is not None  # stage 2 moved: where it linearised is kept
    assert not np.array_equal(state.linearised, state.x)
    lifted, n_lifted = _jacobians(lambda: FullStage()(problem, state))
    # The same stage from stage 2's point (a problem of its own: its own cache).
    problem2, state2 = _after_stage_2(robot, meas)
    plain, n_plain = _jacobians(
        lambda: FullStage()(problem2, state2.but(linearised=None))
    )
    assert n_lifted == n_plain - 1
    assert lifted.linearised is None
    # The same fit, to the stage's statistical tolerance (in characteristic units).
    z = (lifted.x - plain.x) / problem.model.layout.scales
    assert np.abs(z).max() < 1e-2  # (the link moments: the least determined)
    rms = [problem.evaluations.rms_mm(s.model, s.x, s.weights) for s in (lifted, plain)]
    assert rms[0] == pytest.approx(rms[1], rel=1e-6)
