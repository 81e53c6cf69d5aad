"""The design problem: information blocks, priors, identifiability, the set-up."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.geometry import euler_transform
from kinecal.identification import PRIOR_SIGMA
from kinecal.models import ModelInputs
from kinecal.planning import (
    Instrument,
    candidate_inputs,
    design_point,
    design_problem,
    planning_model,
    prior_sigma,
)
from kinecal.robot import load_robot

ROBOT = load_robot("fanuc-lrmate200id")
T_USER_BASE = euler_transform([1.1, 0.9, 0.1, np.radians(160), 0.01, -0.02])
T_TOOL = euler_transform([0.044, -0.06, 0.104, 0.0, 0.0, 0.0])


def poses(rng, n):
    lim = ROBOT.limits * 0.6
    return rng.uniform(lim[:, 0], lim[:, 1], size=(n, 6))


def test_set_up_places_the_user_frame_and_the_tool(rng):
    inst = Instrument("tracker", 1e-5)
    cm, x = planning_model(ROBOT, "full", inst, T_USER_BASE, T_TOOL)
    assert cm.size == 50  # 53 less the tool rotation, unseen by a reflector
    q = poses(rng, 20)
    p = cm.evaluate(x, ModelInputs.make(q)).p_user
    T_ut = T_USER_BASE @ ROBOT.fk_flange(q) @ T_TOOL
    np.testing.assert_allclose(p, T_ut[:, :3, 3], atol=1e-12)
    cm6, _ = planning_model(ROBOT, "kinematic", Instrument("sensor", targets=np.eye(3)))
    assert cm6.size == 30


def test_blocks_are_the_whitened_scaled_jacobian_at_the_design_point(rng):
    inst = Instrument("tracker", 1e-5)
    cm, x = planning_model(ROBOT, "full", inst, T_USER_BASE, T_TOOL)
    q = poses(rng, 200)
    sigma = rng.uniform(5e-6, 2e-5, 200)
    pb = design_problem(cm, x, ModelInputs.make(q), sigma)
    xd = design_point(cm, x, 1e-4)
    np.testing.assert_array_equal(pb.params, xd)
    lam = cm.layout.group_indices("load")
    assert np.all(xd[lam] == 1e-4)
    J = cm.evaluate(xd, ModelInputs.make(q), jacobian=True).J_p
    s = cm.layout.scales
    free = pb.free
    np.testing.assert_allclose(pb.G, J[:, :, free] * s[free], rtol=1e-12, atol=0)
    np.testing.assert_allclose(
        pb.F, J[:, :, free] * s[free] / sigma[:, None, None], rtol=1e-12, atol=0
    )
    W = np.einsum("nip,niq->pq", pb.G, pb.G) / 200
    np.testing.assert_allclose(pb.moment, W, rtol=1e-10, atol=1e-12 * np.abs(W).max())


def test_known_redundancies_are_removed_first(rng):
    cm, x = planning_model(ROBOT, "full", Instrument(), T_USER_BASE, T_TOOL)
    pb = design_problem(cm, x, ModelInputs.make(poses(rng, 500)), 1e-5)
    dropped = {d.name for d in pb.identifiability.dropped}
    # k0 of J1-J3 against the joint offsets and the base rotation; d on parallel axes;
    # lambda1* with J1 parallel to gravity (DESIGN §4)
    assert {"joint1.k0", "joint2.k0", "joint3.k0", "joint1.lambda"} <= dropped
    assert "joint3.d" in dropped or "joint2.d" in dropped
    assert pb.size == int(pb.free.sum()) == cm.size - len(dropped)
    assert not set(pb.names) & dropped


def test_prior_precision_follows_the_calibration_priors(rng):
    cm, x = planning_model(ROBOT, "full", Instrument(), T_USER_BASE, T_TOOL)
    inp = ModelInputs.make(poses(rng, 100))
    pb = design_problem(cm, x, inp, 1e-5)
    s = pb.scales
    for k, name in enumerate(pb.names):
        spec = cm.layout.specs[cm.layout.index(name)]
        sig = PRIOR_SIGMA.get((spec.group, spec.kind))
        if spec.group in ("base", "cam"):
            assert not pb.has_prior[k]
            assert pb.prior_precision[k] == pytest.approx(1e-6)  # vague
        else:
            assert pb.prior_precision[k] == pytest.approx((s[k] / sig) ** 2)
    ps = prior_sigma(cm, "compliance")
    assert np.all(np.isinf(ps[cm.layout.group_indices("joint")]))
    assert np.all(np.isfinite(ps[cm.layout.group_indices("load")]))
    none = design_problem(cm, x, inp, 1e-5, priors="none")
    assert not none.has_prior.any()
    with pytest.raises(
        ValueError, match="priors must be 'none', 'compliance' or 'all'"
    ):
        prior_sigma(cm, "some")


def test_pose_instrument_has_six_rows_and_bad_noise_is_refused(rng):
    inst = Instrument("pose", 2e-5, 3e-5)
    cm, x = planning_model(ROBOT, "kinematic", inst)
    inp = ModelInputs.make(poses(rng, 50))
    pb = design_problem(cm, x, inp, 2e-5, sigma_rot=3e-5)
    assert pb.rows == 6 and pb.G.shape[1] == 3
    J = cm.evaluate(pb.params, inp, orientation=True, jacobian=True)
    s = cm.layout.scales[pb.free]
    np.testing.assert_allclose(pb.F[:, 3:], J.J_w[:, :, pb.free] * s / 3e-5, rtol=1e-12)
    with pytest.raises(ValueError, match="sigma must be positive and finite"):
        design_problem(cm, x, inp, 0.0)
    with pytest.raises(ValueError, match="noise must be positive"):
        Instrument("tracker", -1.0)
    with pytest.raises(ValueError, match="instrument must be one of"):
        Instrument("theodolite")
    with pytest.raises(ValueError, match="a sensor plan needs targets"):
        Instrument("sensor")


def test_sensor_inputs_map_each_pose_onto_its_target(rng):
    targets = np.array([[0.45, 0.1, -0.2], [0.45, -0.1, -0.2], [0.55, 0.0, -0.2]])
    inst = Instrument("sensor", 5e-6, targets=targets)
    cm, x = planning_model(ROBOT, "full", inst)
    q = poses(rng, 30)
    inp, ti = candidate_inputs(cm, x, q, inst)
    out = cm.evaluate(x, inp)
    np.testing.assert_allclose(out.p_user, targets[ti], atol=1e-12)
    # the chosen target is the one closest to the optical axis
    o = cm.evaluate(x, ModelInputs.make(q), orientation=True)
    d = targets[None] - o.p_user[:, None]
    cos = np.einsum("nj,nkj->nk", o.R_user_cam[:, :, 2], d) / np.linalg.norm(d, axis=2)
    np.testing.assert_array_equal(ti, np.argmax(cos, axis=1))
    fixed = np.zeros(30, int)
    inp2, ti2 = candidate_inputs(cm, x, q, inst, fixed)
    assert np.all(ti2 == 0)
    np.testing.assert_allclose(
        cm.evaluate(x, inp2).p_user, targets[[0] * 30], atol=1e-12
    )


def test_fewer_candidate_rows_than_parameters(rng):
    """Three poses (9 rows) cannot determine 50 parameters: the design keeps at most 9,
    and its prediction over those candidates stays finite."""
    from kinecal.planning import plan_poses

    cm, x = planning_model(ROBOT, "full", Instrument(), T_USER_BASE, T_TOOL)
    q = poses(rng, 3)
    pb = design_problem(cm, x, ModelInputs.make(q), 1e-5)
    assert 0 < pb.size <= 9
    pl = plan_poses(cm, x, q, 2)
    assert np.isfinite(pl.planned.heldout_rms) and pl.warnings
