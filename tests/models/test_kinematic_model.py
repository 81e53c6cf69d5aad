"""The unified kinematic model: nominal FK, analytic Jacobians against finite differences."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.geometry import so3_log
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec, _numpy_forward
from kinecal.robot import builtin_robot_names, load_robot
from tests.helpers import assert_jacobian_matches_fd


def _random_inputs(robot, rng, n=30, sets=1, markers=1, p_cam=True):
    lim = np.clip(robot.limits, -3.0, 3.0)
    q = rng.uniform(lim[:, 0], lim[:, 1], size=(n, robot.n_joints))
    return ModelInputs.make(
        q,
        set_index=rng.integers(0, sets, n),
        marker_index=rng.integers(0, markers, n),
        p_cam=rng.normal(size=(n, 3)) * 0.1 if p_cam else None,
        load_scale=rng.uniform(0.5, 1.5, n),
    )


def _generic_params(model, rng, lam):
    p = model.nominal + rng.normal(size=model.size) * model.layout.scales * 3
    for i, s in enumerate(model.layout.specs):
        if s.kind == "compliance":
            p[i] = rng.normal() * lam
        elif s.kind == "moment":
            p[i] = 0.3 + 0.1 * rng.normal()
    return p


@pytest.mark.parametrize("name", builtin_robot_names())
@pytest.mark.parametrize("preset", ["kinematic", "full"])
def test_nominal_parameters_reproduce_nominal_fk(name, preset, rng, kernel):
    robot = load_robot(name)
    spec = ModelSpec.preset(preset, has_self_weight=robot.self_weight is not None)
    model = CalibrationModel(robot, spec)
    inp = _random_inputs(robot, rng, p_cam=False)
    out = model.evaluate(model.nominal, inp, orientation=True)
    T = robot.fk_tool(inp.q_ctrl)
    np.testing.assert_allclose(out.p_user, T[:, :3, 3], atol=1e-14)
    np.testing.assert_allclose(out.R_user_cam, T[:, :3, :3], atol=1e-14)


def _check_all_columns(model, params, inp, cols=None):
    out = model.evaluate(params, inp, orientation=True, jacobian=True)
    cols = np.arange(model.size) if cols is None else np.asarray(cols)

    def f_p(x):
        full = params.copy()
        full[cols] = x
        return model.evaluate(full, inp).p_user

    R0 = out.R_user_cam

    def f_w(x):
        full = params.copy()
        full[cols] = x
        R = model.evaluate(full, inp, orientation=True).R_user_cam
        return so3_log(R @ np.swapaxes(R0, 1, 2))

    names = [model.layout.names[c] for c in cols]
    assert_jacobian_matches_fd(out.J_p[:, :, cols], f_p, params[cols], names=names)
    assert_jacobian_matches_fd(out.J_w[:, :, cols], f_w, params[cols], names=names)


@pytest.mark.parametrize(
    ("name", "spec"),
    [
        ("fanuc-lrmate200id", ModelSpec.preset("full")),
        (
            "fanuc-lrmate200id",
            ModelSpec.preset("rfcm", hayati=(2,), sets=("a", "b"), markers=("m", "n")),
        ),
        ("fanuc-lrmate200id", ModelSpec.preset("ntm", cam_rotation=False)),
        ("ur10", ModelSpec.preset("full", hayati=(2, 3))),
        ("franka-fr3", ModelSpec.preset("full", has_self_weight=False)),
    ],
)
def test_parameter_jacobian_matches_finite_differences(name, spec, rng, kernel):
    """Exact for every column when lambda* = 0 (the torques' geometry dependence vanishes)."""
    robot = load_robot(name)
    model = CalibrationModel(robot, spec)
    inp = _random_inputs(robot, rng, sets=len(spec.sets), markers=len(spec.markers))
    _check_all_columns(model, _generic_params(model, rng, lam=0.0), inp)


@pytest.mark.parametrize(
    ("name", "spec"),
    [
        ("fanuc-lrmate200id", ModelSpec.preset("full")),
        (
            "fanuc-lrmate200id",
            ModelSpec.preset("rfcm", hayati=(2,), markers=("m", "n")),
        ),
        (
            "fanuc-lrmate200id",
            ModelSpec(
                ntm_joints=(1, 2, 3, 5), load=True, link="paper", link_bodies=(2, 3, 5)
            ),
        ),
        ("ur10", ModelSpec.preset("full", hayati=(2, 3))),
    ],
)
def test_jacobian_exact_with_compliance(name, spec, rng, kernel):
    """With lambda* != 0 the torques depend on the geometry; those terms are included."""
    robot = load_robot(name)
    model = CalibrationModel(robot, spec)
    inp = _random_inputs(robot, rng, markers=len(spec.markers))
    _check_all_columns(model, _generic_params(model, rng, lam=1e-3), inp)


def test_joint_jacobian_matches_finite_differences(rng, kernel):
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, ModelSpec.preset("kinematic", sets=("a", "b")))
    inp = _random_inputs(robot, rng, n=5, sets=2, p_cam=True)  # sensor-like points too
    params = _generic_params(model, rng, lam=0.0)
    J = model.joint_jacobian(params, inp)  # (N, 6, n) w.r.t. theta
    assert J.shape == (5, 6, 6)
    C_inv = np.linalg.inv(robot.coupling)
    for k in range(5):
        th0 = robot.theta_from_ctrl(inp.q_ctrl[k])
        R0 = model.evaluate(
            params, inp.subset(np.array([k])), orientation=True
        ).R_user_cam[0]

        def f(th, k=k, R0=R0):
            sub = ModelInputs.make(
                (C_inv @ th)[None],
                set_index=inp.set_index[k : k + 1],
                p_cam=inp.p_cam[k : k + 1],
            )
            o = model.evaluate(params, sub, orientation=True)
            return np.concatenate([o.p_user[0], so3_log(o.R_user_cam[0] @ R0.T)])

        assert_jacobian_matches_fd(J[k], f, th0)


def test_bad_inputs_are_rejected(rng, kernel):
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, ModelSpec.preset("kinematic"))
    with pytest.raises(ValueError, match=r"q_ctrl must have shape \(N, 6\)"):
        model.evaluate(model.nominal, ModelInputs.make(np.zeros((3, 5))))
    with pytest.raises(ValueError, match=r"params must have shape \(30,\)"):
        model.evaluate(np.zeros(3), ModelInputs.make(np.zeros((3, 6))))


def test_jacobian_exact_with_compliance_and_a_prismatic_joint(rng):
    """A prismatic joint whose axis the upstream geometry tilts, gravity not along it."""
    from kinecal.robot import robot_from_dict

    robot = robot_from_dict(
        {
            "name": "slide-6",
            "convention": "dh",
            "units": {"length": "mm", "angle": "deg"},
            "joints": [
                {"theta_offset": 0, "d": 300, "a": 50, "alpha": 80},
                {
                    "theta_offset": 10,
                    "d": 300,
                    "a": 20,
                    "alpha": -70,
                    "type": "prismatic",
                    "limits": [0, 350],
                },
                {"theta_offset": 0, "d": 0, "a": 350, "alpha": 0},
                {"theta_offset": 0, "d": 80, "a": 0, "alpha": 90},
                {"theta_offset": 0, "d": 250, "a": 0, "alpha": -90},
                {"theta_offset": 0, "d": 90, "a": 0, "alpha": 0},
            ],
            "gravity": [2.0, 1.0, -9.0],
            "self_weight": None,
        }
    )
    spec = ModelSpec(ntm_joints=(1, 3), load=True, cam_rotation=True)
    model = CalibrationModel(robot, spec)
    inp = _random_inputs(robot, rng)
    _check_all_columns(model, _generic_params(model, rng, lam=1e-3), inp)


def test_a_kept_forward_state_serves_the_jacobian_at_the_same_point(
    rng, monkeypatch, numpy_kernel
):
    """evaluate(keep=True) then evaluate(jacobian=True, reuse=...) gives exactly the
    fresh Jacobian without computing the forward kinematics again; a state of other
    parameters, inputs, model or without the orientation is not used."""
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, ModelSpec.preset("full", markers=("m", "n")))
    inp = _random_inputs(robot, rng, markers=2)
    params = _generic_params(model, rng, lam=1e-3)
    fresh = model.evaluate(params, inp, orientation=True, jacobian=True)
    kept = model.evaluate(params, inp, orientation=True, keep=True)
    assert kept.forward is not None and fresh.forward is None
    calls = []
    real = CalibrationModel._forward
    monkeypatch.setattr(
        CalibrationModel, "_forward", lambda *a: calls.append(1) or real(*a)
    )
    again = model.evaluate(
        params, inp, orientation=True, jacobian=True, reuse=kept.forward
    )
    assert calls == []
    for name in ("p_user", "R_user_cam", "J_p", "J_w", "theta"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))

    other = params.copy()
    other[model.layout.index("joint2.a")] += 1e-4
    inp_copy = ModelInputs.make(
        inp.q_ctrl,
        marker_index=inp.marker_index,
        p_cam=inp.p_cam,
        load_scale=inp.load_scale,
    )
    position_only = model.evaluate(params, inp, keep=True).forward
    twin = CalibrationModel(robot, model.spec)
    cases = {
        "other parameters": (model, other, inp, kept.forward),
        "an equal but other inputs object": (model, params, inp_copy, kept.forward),
        "no orientation kept": (model, params, inp, position_only),
        "another model": (twin, params, inp, kept.forward),
    }
    for case, (m, x, i, state) in cases.items():
        calls.clear()
        out = m.evaluate(x, i, orientation=True, jacobian=True, reuse=state)
        assert calls == [1], case
        ref = model.evaluate(x, inp, orientation=True, jacobian=True)
        np.testing.assert_array_equal(out.J_p, ref.J_p)
        np.testing.assert_array_equal(out.J_w, ref.J_w)


def test_quantities_of_the_poses_alone_are_computed_once_per_inputs(
    rng, monkeypatch, kernel
):
    """The coupled angles with their cosines and sines and the Fourier bases are kept
    with the inputs object: a second evaluation computes none of them, and its results
    equal those of a fresh inputs object. The returned angles are not the kept array."""
    import kinecal.models._definition as definition_module

    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, ModelSpec.preset("kinematic"))
    full = CalibrationModel(robot, ModelSpec.preset("full"))
    inp = _random_inputs(robot, rng)
    params = _generic_params(full, rng, lam=1e-3)
    calls = []
    real = definition_module.ntm_basis_rows
    monkeypatch.setattr(
        definition_module, "ntm_basis_rows", lambda *a: calls.append(1) or real(*a)
    )
    with pytest.raises(
        ValueError, match="read-only"
    ):  # the kept values cannot go stale
        inp.q_ctrl[0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        inp.subset(np.arange(5)).q_ctrl[0, 0] = 1.0
    first = full.evaluate(params, inp, jacobian=True)
    assert len(calls) == 3  # joints 1-3
    kept = dict(inp._derived)
    with pytest.raises(ValueError, match="read-only"):  # shared by every evaluation
        full.definition.coupled(inp)[1][0, 0] = 0.0
    again = full.evaluate(params, inp, jacobian=True)
    assert len(calls) == 3 and inp._derived.keys() == kept.keys()
    assert all(inp._derived[k] is v for k, v in kept.items())
    fresh = full.evaluate(params, _random_inputs(robot, np.random.default_rng(0)))
    assert not np.allclose(fresh.p_user, first.p_user)  # other poses, other result
    copy = ModelInputs.make(inp.q_ctrl, p_cam=inp.p_cam, load_scale=inp.load_scale)
    ref = full.evaluate(params, copy, jacobian=True)
    for out in (first, again):
        np.testing.assert_array_equal(out.p_user, ref.p_user)
        np.testing.assert_array_equal(out.J_p, ref.J_p)
    # a model without error terms on the angles hands out a copy of them
    x = model.nominal
    theta = model.evaluate(x, inp).theta
    before = theta.copy()
    theta += 1.0
    np.testing.assert_array_equal(model.evaluate(x, inp).theta, before)


def test_row_angles_by_sums_equal_the_direct_sines_and_cosines(rng, kernel):
    """cos/sin of ``C q + offset + dtheta_C`` from those of ``C q`` (offsets by angle
    sums, the NTM errors by the series) equal np.cos/np.sin to rounding. A transmission
    error beyond the series' range takes np.cos itself, and gives the model an offset
    would give."""
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(robot, ModelSpec.preset("full"))
    L = model.layout
    inp = _random_inputs(robot, rng, n=200)
    params = _generic_params(model, rng, lam=1e-3)
    ntm = L.group_indices("ntm")
    params[ntm] = rng.normal(size=ntm.size) * 1e-3
    defn = model.definition
    rows = defn.rows(params)
    coupled = defn.coupled(inp)
    dth, _ = _numpy_forward.ntm_errors(defn, params, inp)
    ct, st = _numpy_forward.row_trig(defn, rows, coupled, dth)
    th = robot.coupling @ inp.q_ctrl.T + rows[:, 0, None] + dth
    np.testing.assert_allclose(ct, np.cos(th), rtol=0, atol=1e-15)
    np.testing.assert_allclose(st, np.sin(th), rtol=0, atol=1e-15)

    big = params.copy()
    big[L.index("joint2.k0")] = 0.05  # rad, beyond the series
    big_dth = _numpy_forward.ntm_errors(defn, big, inp)[0]
    assert _numpy_forward.row_trig(defn, rows, coupled, big_dth) is None
    shifted = big.copy()
    shifted[L.index("joint2.k0")] = 0.0
    shifted[L.index("joint2.theta_offset")] += 0.05
    np.testing.assert_allclose(
        model.evaluate(big, inp).p_user,
        model.evaluate(shifted, inp).p_user,
        rtol=0,
        atol=1e-12,
    )


def test_issue_19_the_model_definition_is_frozen_and_survives_pickling(rng):
    """The definition's tables cannot be changed behind the evaluators' back, also after
    a round trip through pickle (results of worker processes)."""
    import pickle

    model = CalibrationModel(
        load_robot("fanuc-lrmate200id"), ModelSpec.preset("full", sets=("", "b"))
    )
    again = pickle.loads(pickle.dumps(model))
    for m in (model, again):
        for name in ("nominal", "base_index", "cam_index", "R_ref_base", "g_hat"):
            with pytest.raises(ValueError, match="read-only"):
                getattr(m, name)[0] = 0.0
        with pytest.raises(AttributeError):
            m.definition.row_idx = None
    inp = _random_inputs(model.robot, rng, sets=2)
    x = _generic_params(model, rng, lam=1e-3)
    a = model.evaluate(x, inp, orientation=True, jacobian=True)
    b = again.evaluate(x, inp, orientation=True, jacobian=True)
    for name in ("p_user", "R_user_cam", "J_p", "J_w", "theta"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
