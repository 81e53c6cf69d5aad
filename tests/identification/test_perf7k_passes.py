"""Issue 36: stage 3's lifted start linearises at stage 1's solution, where stage 2
linearised (its Jacobian, with the product columns, kept from stage 1): one Jacobian pass
fewer than at stage 2's point, the same fit to the stages' tolerance; the calibration of
500 twin poses in 8 Jacobian passes (10 before), its nominal check in 1; the
identifiability analysis from registration's Jacobian with the product columns."""

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


def test_the_calibration_takes_eight_jacobian_passes(twin500):
    robot, meas = twin500
    res, n_fit = _jacobians(lambda: calibrate(robot, meas, "full"))
    found, n_check = _jacobians(lambda: nominal_check(res, robot, meas))
    assert res.success
    assert n_fit <= 8 and n_check <= 1
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


@pytest.mark.parametrize("model", ["full", "rfcm", "kinematic"])
def test_the_identifiability_analysis_takes_registrations_jacobian(
    twin500, model, monkeypatch
):
    """At the registered point (compliances and link moments zero) the analysis's
    normal matrix at the generic point comes from registration's Jacobian with the
    product columns: no Jacobian pass, the same decisions as the direct evaluation at
    the generic point."""
    import kinecal.identification._stages as st

    robot, meas = twin500
    problem = Problem.make(robot, meas, model)
    registered = st.Register()(problem, problem.start())
    found, n = _jacobians(lambda: st.Identify()(problem, registered))
    assert n == 0
    monkeypatch.setattr(st, "_generic_normal", lambda *a: None)
    direct, n_direct = _jacobians(lambda: st.Identify()(problem, registered))
    assert n_direct == 1
    a, b = found.identifiability, direct.identifiability
    np.testing.assert_array_equal(a.free, b.free)
    assert [d.name for d in a.dropped] == [d.name for d in b.dropped]
    assert [d.code for d in found.diagnostics] == [d.code for d in direct.diagnostics]
