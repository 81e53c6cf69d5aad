"""Identifiability analysis: the known redundancies are found and fixed, uniquely."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import IdentifiabilityError
from kinecal.identification import Measurements, analyse_identifiability, calibrate
from kinecal.models import (
    CalibrationModel,
    ModelInputs,
    ModelSpec,
    ParameterLayout,
    ParamSpec,
)
from kinecal.robot import dump_robot, load_robot, robot_from_dict
from kinecal.simulation import random_truth


def _names(res):
    return {d.name for d in res.identifiability.dropped}


def test_known_redundancies_of_the_full_model(exp2_exact):
    e = exp2_exact
    res = calibrate(e.truth.robot, e.train, "full")
    dropped = _names(res)
    # DESIGN §4: k0 of J1-J3 vs offsets/base rotation, lambda1 with J1 parallel to
    # gravity, d on the parallel J2/J3 axes; and s1 vs the first J2 harmonic (level base).
    assert {
        "joint1.k0",
        "joint2.k0",
        "joint3.k0",
        "joint1.lambda",
        "joint3.d",
    } <= dropped
    assert dropped & {"joint2.ka1", "joint2.kb1"}
    partners = {d.name: [n for n, _ in d.partners] for d in res.identifiability.dropped}
    assert "joint2.theta_offset" in partners["joint2.k0"]
    assert "joint2.d" in partners["joint3.d"]
    assert partners["joint1.lambda"] == []  # no effect at all
    # Unique result: held parameters keep their start values, others are estimated.
    idx = res.model.layout.index("joint3.d")
    assert res.calibrated.status[idx] == "unidentifiable"
    assert res.params[idx] == res.registered[idx]
    assert np.isnan(res.std[idx])


def test_hayati_row_removes_the_parallel_axis_redundancy(exp2_exact):
    from kinecal.identification import spec_for

    e = exp2_exact
    spec = spec_for(e.truth.robot, e.train, "kinematic", hayati=(2,))
    res = calibrate(e.truth.robot, e.train, spec)
    assert not any(n.endswith(".d") for n in _names(res))
    assert "joint2.beta" in res.model.layout


def test_tilted_base_makes_lambda1_identifiable(rng):
    doc = dump_robot(load_robot("fanuc-lrmate200id"))
    doc["gravity"] = [np.sin(0.3), 0.0, -np.cos(0.3)]
    tilted = robot_from_dict(doc)
    truth = random_truth(tilted, seed=3)
    q = rng.uniform(tilted.limits[:, 0] * 0.5, tilted.limits[:, 1] * 0.5, size=(150, 6))
    p, _ = truth.evaluate(q)
    meas = Measurements("point", q, p + rng.normal(size=p.shape) * 5e-6)
    res = calibrate(tilted, meas, "full")
    assert "joint1.lambda" not in _names(res)
    assert "joint1.k0" in _names(res)


def test_zero_and_duplicate_columns_are_flagged():
    layout = ParameterLayout(
        [ParamSpec(n, "length", "base") for n in ("a", "b", "c", "d")]
    )
    rng = np.random.default_rng(0)
    J = rng.normal(size=(50, 4))
    J[:, 2] = 0.0  # no effect
    J[:, 3] = 2.0 * J[:, 0] - J[:, 1]  # combination of a and b
    out = analyse_identifiability(J, layout, np.ones(4, bool))
    assert [d.name for d in out.dropped] == ["c", "d"]
    coef = dict(out.dropped[1].partners)
    assert coef["a"] == pytest.approx(2.0) and coef["b"] == pytest.approx(-1.0)
    assert out.rank == 2 and np.isfinite(out.condition_number)


def test_too_few_poses_is_a_clear_error(exp2_exact):
    e = exp2_exact
    with pytest.raises(
        IdentifiabilityError,
        match=r"12 poses give 36 residuals, but the 'full' model has 50",
    ):
        calibrate(e.truth.robot, e.train.subset(np.arange(12)), "full")
    with pytest.raises(IdentifiabilityError, match="measure at least"):
        calibrate(e.truth.robot, e.train.subset(np.arange(5)), "kinematic")


def test_identifiability_decisions_do_not_depend_on_units(exp2_exact):
    """Relative tolerances only: the same data in mm-scaled model units give the same rank."""
    e = exp2_exact
    robot = e.truth.robot
    m = CalibrationModel(robot, ModelSpec.preset("full", cam_rotation=False))
    out = m.evaluate(m.nominal, ModelInputs.make(e.train.q_ctrl), jacobian=True)
    J = out.J_p.reshape(-1, m.size)
    a = analyse_identifiability(J, m.layout, np.ones(m.size, bool))
    b = analyse_identifiability(J * 1e3, m.layout, np.ones(m.size, bool))
    assert [d.name for d in a.dropped] == [d.name for d in b.dropped]


def test_robot_file_priors_reach_the_identification():
    from dataclasses import replace

    from kinecal.identification import CalibrationOptions
    from kinecal.identification._calibrate import build_prior
    from kinecal.models import CalibrationModel, ModelSpec
    from kinecal.robot import load_robot

    robot = load_robot("fanuc-lrmate200id")
    wide = replace(
        robot, prior_sigma={("joint", "length"): 7e-3, ("ntm", "ntm"): np.inf}
    )
    cm = CalibrationModel(wide, ModelSpec.preset("full"))
    pr = build_prior(cm, cm.nominal, CalibrationOptions())
    names = cm.layout.names
    assert pr.sigma[names.index("joint2.a")] == pytest.approx(7e-3)
    assert pr.sigma[names.index("joint2.alpha")] == pytest.approx(np.radians(0.1))
    assert np.isinf(pr.sigma[names.index("joint1.ka1")])
    pr2 = build_prior(
        cm,
        cm.nominal,
        CalibrationOptions().tuned(prior_sigma={"joint2.a": 1e-4}, prior_scale=2),
    )
    assert pr2.sigma[names.index("joint2.a")] == pytest.approx(1e-4)
    assert pr2.sigma[names.index("joint3.a")] == pytest.approx(14e-3)
