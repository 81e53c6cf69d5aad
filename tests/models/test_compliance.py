"""Joint compliance terms against physics: virtual work, hand computations, tilted bases."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal.models import (
    CalibrationModel,
    ModelInputs,
    ModelSpec,
    _numpy_forward,
    chain_frames,
    load_torques,
    ntm_basis,
)
from kinecal.models._compliance import general_link_torque_basis, link_torque_basis
from kinecal.robot import load_robot, robot_from_dict
from tests.helpers import fd_jacobian

FANUC = load_robot("fanuc-lrmate200id")


def _fanuc_chain(theta):
    """Standard-DH frames of the nominal LR Mate for kinematic angles theta (N, 6)."""
    ch = FANUC.dh_chain()
    return chain_frames(theta + ch.theta_offset, ch.d, ch.a, ch.alpha)


def _random_gravity(rng):
    return Rotation.from_rotvec(rng.normal(size=3) * 0.3).apply([0.0, 0.0, -1.0])


def test_load_torques_equal_virtual_work(rng):
    """tau = -dV/dtheta with V = -g·p_load (unit weight), for any gravity direction."""
    theta0 = rng.uniform(-2, 2, size=(8, 6))
    t_tool = np.array([0.03, -0.02, 0.25])
    for g_hat in ([0.0, 0.0, -1.0], _random_gravity(rng)):
        g_hat = np.asarray(g_hat)
        fr = _fanuc_chain(theta0)
        p_load = fr.o[:, 6] + fr.R[:, 6] @ t_tool
        tau = load_torques(fr, p_load.T, g_hat, np.zeros(6, bool)).T  # (N, n)
        for k in range(8):

            def potential(th, k=k, g_hat=g_hat):
                f = _fanuc_chain(th[None])
                return -g_hat @ (f.o[0, 6] + f.R[0, 6] @ t_tool)

            dV = fd_jacobian(lambda th: np.array([potential(th)]), theta0[k])[0]
            np.testing.assert_allclose(tau[k], -dV, atol=1e-8)
        if g_hat[2] == -1.0:
            np.testing.assert_allclose(
                tau[:, 0], 0.0, atol=1e-15
            )  # J1 parallel to gravity


def _planar_robot():
    return robot_from_dict(
        {
            "name": "planar",
            "convention": "dh",
            "units": {"length": "m", "angle": "deg"},
            "joints": [
                {"theta_offset": 0, "d": 0, "a": 0, "alpha": 90},
                {"theta_offset": 0, "d": 0, "a": 0.5, "alpha": 0},
                {"theta_offset": 0, "d": 0, "a": 0.4, "alpha": 0},
            ],
            "self_weight": {"shoulder": 2, "elbow": 3, "wrist_frame": 3},
        }
    )


def test_link_torques_planar_two_link_hand_computation(rng):
    """J2 axis = -y, links in the x-z plane.

    tau2 = -s1 cos t2 - s2 cos(t2 + t3) and tau3 = -s2 cos(t2 + t3).
    """
    r = _planar_robot()
    ch = r.dh_chain()
    th = np.column_stack([np.zeros(20), rng.uniform(-3, 3, 20), rng.uniform(-3, 3, 20)])
    fr = chain_frames(th + ch.theta_offset, ch.d, ch.a, ch.alpha)
    T = link_torque_basis(fr, np.array([0.0, 0.0, -1.0]), 2, 3, 3, 1.0, "paper")
    s1, s2 = 0.7, 0.2
    tau = np.einsum("jsn,s->nj", T, [s1, s2])
    t2, t23 = th[:, 1], th[:, 1] + th[:, 2]
    np.testing.assert_allclose(tau[:, 0], 0.0, atol=1e-15)
    np.testing.assert_allclose(
        tau[:, 1], -s1 * np.cos(t2) - s2 * np.cos(t23), atol=1e-14
    )
    np.testing.assert_allclose(tau[:, 2], -s2 * np.cos(t23), atol=1e-14)


def _point_mass_torques(theta, g_hat, masses):
    """Brute force: tau_j = -dV/dtheta_j for point masses (body k, local point c, mass m)."""

    def V(th):
        f = _fanuc_chain(th[None])
        return -sum(m * g_hat @ (f.o[0, k] + f.R[0, k] @ c) for k, c, m in masses)

    return np.array([-fd_jacobian(lambda th: np.array([V(th)]), t)[0] for t in theta])


def test_paper_link_model_matches_point_masses_under_any_tilt(rng):
    """Upper-arm mass on the J2-J3 line and forearm mass on the J3-wrist line (the lumped
    model's assumptions): s1 = m_u A2 + m_f L2, s2 = m_f A3, for J2 and J3 at any tilt."""
    a2 = FANUC.dh_chain().a[1]
    m_u, A2, m_f, A3 = 1.3, 0.15, 0.9, 0.2
    theta = rng.uniform(-1.5, 1.5, size=(6, 6))
    for g_hat in (np.array([0.0, 0.0, -1.0]), _random_gravity(rng)):
        fr = _fanuc_chain(theta)
        T = link_torque_basis(fr, g_hat, 2, 3, 4, 1.0, "paper")
        tau = np.einsum("jsn,s->nj", T, [m_u * A2 + m_f * a2, m_f * A3])
        tau_j1 = []
        for k in range(6):
            f1 = _fanuc_chain(theta[k : k + 1])
            o2, o3, R3 = f1.o[0, 2], f1.o[0, 3], f1.R[0, 3]
            w = f1.o[0, 4] - o2
            z = f1.R[0, 2, :, 2]
            u = (w - (w @ z) * z) / np.linalg.norm(w - (w @ z) * z)
            masses = [
                (
                    2,
                    np.array([A2 - a2, 0.0, 0.0]),
                    m_u,
                ),  # on the J2-J3 line, rigid with body 2
                (
                    3,
                    R3.T @ (o2 + A3 * u - o3),
                    m_f,
                ),  # on the J3-wrist line, rigid with body 3
            ]
            ref = _point_mass_torques(theta[k : k + 1], g_hat, masses)[0]
            np.testing.assert_allclose(tau[k, 1:3], ref[1:3], atol=1e-8)
            tau_j1.append(ref[0])
        if g_hat[2] == -1.0:
            np.testing.assert_allclose(tau_j1, 0.0, atol=1e-8)  # J1 parallel to gravity
        else:
            # A tilted base loads J1 too; the lumped model leaves it out, the general one has it.
            assert np.abs(tau_j1).max() > 1e-3


def test_general_link_model_matches_point_masses_on_every_joint(rng):
    masses = [
        (2, rng.normal(size=3) * 0.1, 2.0),
        (3, rng.normal(size=3) * 0.1, 1.0),
        (5, rng.normal(size=3) * 0.05, 0.3),
    ]
    theta = rng.uniform(-1.5, 1.5, size=(5, 6))
    g_hat = _random_gravity(rng)
    fr = _fanuc_chain(theta)
    T = general_link_torque_basis(fr, g_hat, (2, 3, 5), np.zeros(6, bool))
    coef = np.concatenate([[m, *(m * c)] for _, c, m in masses])
    tau = np.einsum("jsn,s->nj", T, coef)
    ref = _point_mass_torques(theta, g_hat, masses)
    np.testing.assert_allclose(tau, ref, atol=1e-8)


def test_tilting_the_base_rotates_gravity_in_the_model(rng):
    level = FANUC
    tilted = robot_from_dict(
        {
            "name": "tilted",
            "convention": "dh",
            "units": {"length": "mm", "angle": "deg"},
            "joints": [
                {
                    "theta_offset": np.degrees(j.theta_offset),
                    "d": j.d * 1e3,
                    "a": j.a * 1e3,
                    "alpha": np.degrees(j.alpha),
                }
                for j in level.joints
            ],
            "coupling": [{"joint": 3, "from": 2, "factor": 1}],
            "gravity": [np.sin(0.2), 0.0, -np.cos(0.2)],
        }
    )
    spec = ModelSpec.preset("full")
    m_level = CalibrationModel(level, spec)
    m_tilt = CalibrationModel(tilted, spec)
    q = rng.uniform(-1, 1, size=(50, 6))
    p = m_level.nominal.copy()
    p[m_level.layout.indices([f"joint{j}.lambda" for j in range(1, 7)])] = 2e-4
    p[m_level.layout.indices(["link.s1", "link.s2"])] = [0.3, 1.8]
    inp = ModelInputs.make(q)
    d_level = m_level.evaluate(p, inp).theta - level.theta_from_ctrl(q)
    d_tilt = m_tilt.evaluate(p, inp).theta - level.theta_from_ctrl(q)
    np.testing.assert_allclose(
        d_level[:, 0], 0.0, atol=1e-15
    )  # J1 vertical: no deflection
    assert np.abs(d_tilt[:, 0]).max() > 1e-5  # tilted: the payload loads J1
    assert np.abs(d_tilt[:, 1:3] - d_level[:, 1:3]).max() > 1e-6


def test_ntm_basis_columns():
    q = np.linspace(-3, 3, 7)
    B = ntm_basis(q, 2, True)
    np.testing.assert_allclose(
        B,
        np.column_stack(
            [np.ones(7), np.cos(q), np.sin(q), np.cos(2 * q), np.sin(2 * q)]
        ),
    )
    B4 = ntm_basis(q, 4, False)  # higher harmonics come from angle sums
    h = np.arange(1, 5)
    np.testing.assert_allclose(B4[:, 0::2], np.cos(np.outer(q, h)), atol=1e-14)
    np.testing.assert_allclose(B4[:, 1::2], np.sin(np.outer(q, h)), atol=1e-14)


def test_paper_sized_values_deflect_tens_of_micrometres(rng):
    """Table 7 values: the compliance terms move the tool by tens of micrometres."""
    model = CalibrationModel(FANUC, ModelSpec.preset("full", cam_rotation=False))
    L = model.layout
    p = model.nominal.copy()
    p[L.indices(["cam.x", "cam.y", "cam.z"])] = (
        np.array([44.200, -60.458, 104.009]) * 1e-3
    )
    p[L.indices([f"joint{j}.lambda" for j in range(1, 7)])] = (
        np.array([-1.289, 0.0668, 0.0522, 0.138, 0.732, -0.117]) * 1e-3
    )
    p[L.indices(["link.s1", "link.s2"])] = [0.307383, 1.841103]
    ntm = (
        np.array(
            [  # k0, ka1, kb1, ka2, kb2 per joint (Table 7, x 1e-3 rad)
                [0.158, -0.120, -0.0512, -0.206, 0.0819],
                [0.403, -0.0430, -0.0553, 0.0217, 0.0188],
                [-0.0281, -0.503, 0.144, -0.418, 0.183],
            ]
        )
        * 1e-3
    )
    for j in range(3):
        p[
            L.indices([f"joint{j + 1}.{c}" for c in ("k0", "ka1", "kb1", "ka2", "kb2")])
        ] = ntm[j]
    lim = FANUC.limits
    q = rng.uniform(lim[:, 0] * 0.5, lim[:, 1] * 0.5, size=(2000, 6))
    inp = ModelInputs.make(q)
    kin_only = p.copy()
    kin_only[L.group_indices("ntm")] = 0.0
    kin_only[L.group_indices("load")] = 0.0
    d_all = np.linalg.norm(
        model.evaluate(p, inp).p_user - model.evaluate(kin_only, inp).p_user, axis=1
    )
    rms_um = np.sqrt(np.mean(d_all**2)) * 1e6
    assert 20 < rms_um < 1000, rms_um  # NTM k0 terms alone shift by ~0.1-0.3 mm
    k0_free = kin_only.copy()
    k0_free[L.group_indices("load")] = p[L.group_indices("load")]
    k0_free[L.group_indices("link")] = p[L.group_indices("link")]
    d_gravity = np.linalg.norm(
        model.evaluate(k0_free, inp).p_user - model.evaluate(kin_only, inp).p_user,
        axis=1,
    )
    grav_um = np.sqrt(np.mean(d_gravity**2)) * 1e6
    assert 5 < grav_um < 200, grav_um  # payload and link weight: tens of micrometres


def test_link_bases_vanish_outside_their_patterns(rng):
    """The (joint, column) patterns list every entry of the link bases that can be non-zero."""
    from kinecal.models._compliance import general_link_pattern, link_torque_pattern

    theta = rng.uniform(-2, 2, size=(40, 6))
    fr = _fanuc_chain(theta)
    g_hat = _random_gravity(rng)  # a tilted base, so that no entry vanishes by symmetry
    cases = [
        (link_torque_basis(fr, g_hat, 2, 3, 4, 1.0, m), link_torque_pattern(m, 2, 3))
        for m in ("paper", "rfcm")
    ]
    # The general model on a skew arm (parallel axes give geometric zeros: a moment along
    # an axis parallel to the joint's exerts no torque about it).
    skew = chain_frames(
        theta,
        rng.uniform(0.1, 0.3, 6),
        rng.uniform(0.1, 0.3, 6),
        rng.uniform(0.3, 1.2, 6),
    )
    prismatic = np.array([False, False, True, False, False, False])
    cases.append(
        (
            general_link_torque_basis(skew, g_hat, (2, 4), prismatic),
            general_link_pattern((2, 4), prismatic),
        )
    )
    for T, pattern in cases:
        inside = np.zeros(T.shape[:2], bool)
        for j, k in pattern:
            inside[j - 1, k] = True
        assert np.all(T[~inside] == 0.0)
        assert np.all(np.abs(T[inside]).max(axis=-1) > 1e-3)


@pytest.mark.parametrize(
    "spec",
    [
        ModelSpec.preset("full"),
        ModelSpec.preset("rfcm", sets=("a", "b")),
        ModelSpec(ntm_joints=(2,), load=True, link="paper", link_bodies=(2, 3)),
    ],
)
def test_link_product_columns(spec, rng, kernel):
    """Column of lambda*_j s_k = d p / d theta_j (joint Jacobian) times the torque per unit
    s_k at the undeflected pose; the columns of s_k are sum_j lambda*_j times them."""
    model = CalibrationModel(FANUC, spec)
    L = model.layout
    p = model.nominal + rng.normal(size=model.size) * L.scales
    p[L.group_indices("load")] = rng.normal(size=6) * 1e-3
    p[L.group_indices("link")] = rng.uniform(0.2, 2.0, L.group_indices("link").size)
    q = rng.uniform(-1.5, 1.5, size=(25, 6))
    inp = ModelInputs.make(
        q,
        set_index=rng.integers(0, len(spec.sets), 25),
        p_cam=rng.normal(size=(25, 3)) * 0.05,
    )
    out = model.evaluate(p, inp, jacobian=True, products=True)
    pairs = model.link_products
    assert out.J_p.shape == (25, 3, model.size + len(pairs))
    np.testing.assert_array_equal(
        out.J_p[:, :, : model.size],
        model.evaluate(p, inp, jacobian=True).J_p,
    )
    # joint Jacobian at the deflected pose, link torques at the undeflected one
    Jq = model.joint_jacobian(p, inp)[:, :3]
    defn = model.definition
    theta0 = FANUC.coupling @ q.T + _numpy_forward.ntm_errors(defn, p, inp)[0]
    fr0 = _numpy_forward.chain(defn, theta0, defn.rows(p))
    T = _numpy_forward.link_basis(defn, fr0)  # (n, n_link, N)
    s_cols = np.zeros((25, 3, L.group_indices("link").size))
    for i, (lam, s) in enumerate(pairs):
        j = lam - model.layout.index("joint1.lambda")
        k = s - L.group_indices("link")[0]
        col = out.J_p[:, :, model.size + i]
        np.testing.assert_allclose(col, Jq[:, :, j] * T[j, k][:, None], atol=1e-12)
        s_cols[:, :, k] += p[lam] * col
    np.testing.assert_allclose(
        s_cols, out.J_p[:, :, L.group_indices("link")], rtol=1e-12, atol=1e-15
    )
