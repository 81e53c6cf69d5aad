"""Issue 38 point 2: kinecal's ISO 9283 AP, RP, AD, RD equal an independent
implementation of the standard's formulas (written here, plain loops, scipy's Euler
angles) and recover a known bias (accuracy) and noise (repeatability)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal.errors import DataError
from kinecal.iso9283 import (
    POINT_LABELS,
    distance_characteristics,
    orientation_abc,
    pose_characteristics,
)

# Mean and std of the distance of a 3-D isotropic Gaussian (sigma 1) to its centre
# (Maxwell distribution): RP of such noise tends to (MAXWELL_MEAN + 3 MAXWELL_STD) sigma.
MAXWELL_MEAN = 2.0 * math.sqrt(2.0 / math.pi)
MAXWELL_STD = math.sqrt((3.0 * math.pi - 8.0) / math.pi)


def standard_ap_rp(xs, cmd):
    """ISO 9283 7.2.1 and 7.2.2 for one point, from the formulas, loop by loop."""
    n = len(xs)
    xb = sum(x[0] for x in xs) / n
    yb = sum(x[1] for x in xs) / n
    zb = sum(x[2] for x in xs) / n
    ap = math.sqrt((xb - cmd[0]) ** 2 + (yb - cmd[1]) ** 2 + (zb - cmd[2]) ** 2)
    ls = [math.sqrt((x[0] - xb) ** 2 + (x[1] - yb) ** 2 + (x[2] - zb) ** 2) for x in xs]
    lb = sum(ls) / n
    sl = math.sqrt(sum((v - lb) ** 2 for v in ls) / (n - 1))
    return ap, (xb - cmd[0], yb - cmd[1], zb - cmd[2]), lb + 3 * sl


def standard_orientation(angles, cmd):
    """AP_a = a_bar - a_c, RP_a = 3 S_a (one angle)."""
    n = len(angles)
    mean = sum(angles) / n
    s = math.sqrt(sum((a - mean) ** 2 for a in angles) / (n - 1))
    return mean - cmd, 3 * s


def standard_distance(p1s, p2s, c1, c2):
    """ISO 9283 7.4: AD_P = D_bar - D_c, RD = 3 S_D."""
    n = len(p1s)
    d = [math.dist(a, b) for a, b in zip(p1s, p2s)]
    db = sum(d) / n
    s = math.sqrt(sum((v - db) ** 2 for v in d) / (n - 1))
    return db - math.dist(c1, c2), 3 * s


def _cube_data(rng, n_cycles, bias, sigma, sigma_rot=0.0, rot_bias=None):
    """Attained and command poses of P1..P5, cycles in the standard's order."""
    cmd_p = rng.uniform(-0.3, 0.3, (5, 3)) + np.array([0.5, 0.0, 0.3])
    cmd_R = Rotation.from_euler("xyz", [np.pi, 0.1, 0.2]).as_matrix()
    order = np.array([0, 4, 3, 2, 1])
    idx = np.tile(order, n_cycles)
    cyc = np.repeat(np.arange(1, n_cycles + 1), 5)
    p_cmd = cmd_p[idx]
    p_att = p_cmd + bias[idx] + rng.normal(0.0, sigma, p_cmd.shape)
    R_cmd = np.broadcast_to(cmd_R, (idx.size, 3, 3))
    turn = Rotation.from_rotvec(rng.normal(0.0, sigma_rot, (idx.size, 3)))
    if rot_bias is not None:  # about the base z axis: changes c only
        turn = Rotation.from_rotvec([0.0, 0.0, rot_bias]) * turn
    R_att = (turn * Rotation.from_matrix(R_cmd)).as_matrix()
    return p_att, p_cmd, R_att, R_cmd, idx, cyc


def test_orientation_angles_are_the_standards_a_b_c_about_x_y_z():
    rng = np.random.default_rng(0)
    abc = rng.uniform([-3, -1.5, -3], [3, 1.5, 3], (50, 3))
    R = Rotation.from_euler("xyz", abc).as_matrix()  # extrinsic x, then y, then z
    np.testing.assert_allclose(orientation_abc(R), abc, atol=1e-12)


def test_issue_38_ap_rp_equal_an_independent_implementation_of_the_standard(rng):
    bias = rng.normal(0.0, 2e-4, (5, 3))
    p_att, p_cmd, R_att, R_cmd, idx, _ = _cube_data(rng, 30, bias, 3e-5, 1e-4)
    figs = pose_characteristics(
        p_att, p_cmd, idx, POINT_LABELS, R_attained=R_att, R_command=R_cmd
    )
    eul_att = Rotation.from_matrix(R_att).as_euler("xyz")
    eul_cmd = Rotation.from_matrix(R_cmd).as_euler("xyz")
    for k, f in enumerate(figs):
        rows = [i for i in range(len(idx)) if idx[i] == k]
        xs = [tuple(p_att[i]) for i in rows]
        ap, ap_xyz, rp = standard_ap_rp(xs, tuple(p_cmd[rows[0]]))
        assert f.label == POINT_LABELS[k] and f.n == 30
        assert f.ap == pytest.approx(ap, rel=1e-12)
        np.testing.assert_allclose(f.ap_xyz, ap_xyz, rtol=1e-10, atol=1e-15)
        assert f.rp == pytest.approx(rp, rel=1e-12)
        for j in range(3):  # a, b, c (no wrap near these angles but a = pi: wrap)
            ang = [
                (eul_att[i, j] - eul_cmd[i, j] + np.pi) % (2 * np.pi) - np.pi
                for i in rows
            ]
            ap_a, rp_a = standard_orientation(ang, 0.0)
            assert f.ap_abc[j] == pytest.approx(ap_a, abs=1e-12)
            assert f.rp_abc[j] == pytest.approx(rp_a, rel=1e-9)


def test_issue_38_ad_rd_equal_an_independent_implementation(rng):
    bias = rng.normal(0.0, 2e-4, (5, 3))
    p_att, p_cmd, _, _, idx, cyc = _cube_data(rng, 30, bias, 3e-5)
    d = distance_characteristics(p_att, p_cmd, idx, cyc, POINT_LABELS)
    r2 = [i for i in range(len(idx)) if idx[i] == 1]
    r4 = [i for i in range(len(idx)) if idx[i] == 3]
    ad, rd = standard_distance(
        [p_att[i] for i in r2], [p_att[i] for i in r4], p_cmd[r2[0]], p_cmd[r4[0]]
    )
    assert d is not None and d.pair == ("P2", "P4") and d.n == 30
    assert d.ad == pytest.approx(ad, rel=1e-10)
    assert d.rd == pytest.approx(rd, rel=1e-10)
    # a cycle without P4: the pair is formed over the cycles that hold both
    keep = ~((idx == 3) & (cyc == 7))
    d29 = distance_characteristics(
        p_att[keep], p_cmd[keep], idx[keep], cyc[keep], POINT_LABELS
    )
    assert d29 is not None and d29.n == 29


def test_issue_38_known_bias_and_noise_are_recovered(rng):
    """AP recovers the bias within its sampling error, RP the noise's 3-D spread."""
    sigma, sigma_rot, n = 2e-5, 5e-5, 30
    bias = np.array(
        [[1e-4, 0, 0], [0, 2e-4, 0], [0, 0, 3e-4], [5e-5, 5e-5, 0], [0, 0, 0]]
    )
    p_att, p_cmd, R_att, R_cmd, idx, _ = _cube_data(
        rng, n, bias, sigma, sigma_rot, rot_bias=2e-4
    )
    figs = pose_characteristics(
        p_att, p_cmd, idx, POINT_LABELS, R_attained=R_att, R_command=R_cmd
    )
    se = sigma / math.sqrt(n)  # per-axis standard error of the barycentre
    for k, f in enumerate(figs):
        np.testing.assert_allclose(f.ap_xyz, bias[k], atol=4 * se)
        assert abs(f.ap - np.linalg.norm(bias[k])) < 4 * math.sqrt(3) * se
        assert abs(f.ap_abc[2] - 2e-4) < 4 * sigma_rot / math.sqrt(n)
        assert np.all(np.abs(f.ap_abc[:2]) < 4 * sigma_rot / math.sqrt(n))
    rp_true = (MAXWELL_MEAN + 3 * MAXWELL_STD) * sigma
    rp_mean = np.mean([f.rp for f in figs])
    # sampling std of one RP with 30 cycles is about 0.3 sigma; five points averaged
    assert abs(rp_mean - rp_true) < 4 * 0.3 * sigma / math.sqrt(5)
    # many cycles: the estimate converges to the value the noise implies
    p_att, p_cmd, _, _, idx, _ = _cube_data(rng, 4000, bias, sigma)
    big = pose_characteristics(p_att, p_cmd, idx, POINT_LABELS)
    for f in big:
        assert f.rp == pytest.approx(rp_true, rel=0.03)
        assert f.l_bar == pytest.approx(MAXWELL_MEAN * sigma, rel=0.02)


def test_issue_38_too_few_cycles_is_a_clear_error(rng):
    bias = np.zeros((5, 3))
    p_att, p_cmd, _, _, idx, cyc = _cube_data(rng, 3, bias, 1e-5)
    keep = ~((idx == 2) & (cyc > 1))  # P3 measured once
    with pytest.raises(
        DataError, match=r"test point P3: 1 cycle\(s\) measured; expected at least 2"
    ):
        pose_characteristics(p_att[keep], p_cmd[keep], idx[keep], POINT_LABELS)
    with pytest.raises(ValueError, match="must both have shape"):
        pose_characteristics(p_att[:, :2], p_cmd, idx, POINT_LABELS)


def test_issue_38_orientation_ad_rd_equal_an_independent_implementation(rng):
    """ISO 9283 7.4 for orientation: D_aj = a_1j - a_2j, AD_a = mean(D_aj) - D_ca,
    RD_a = 3 S_Da, with P2 and P4 commanded at different orientations (and one angle
    near +-pi, where the angles wrap)."""
    n = 30
    cmd_abc = rng.uniform(-1.0, 1.0, (5, 3))
    cmd_abc[1, 0] = np.pi - 1e-3  # P2's a close to pi: attained values wrap to -pi
    idx = np.tile(np.array([0, 4, 3, 2, 1]), n)
    cyc = np.repeat(np.arange(1, n + 1), 5)
    p_cmd = rng.uniform(-0.3, 0.3, (5, 3))[idx]
    p_att = p_cmd + rng.normal(0.0, 2e-5, p_cmd.shape)
    R_cmd = Rotation.from_euler("xyz", cmd_abc[idx]).as_matrix()
    bias = np.array([0.0, 0.0, 3e-4])  # about the base z: P2 and P4 alike
    turn = Rotation.from_rotvec(rng.normal(0.0, 2e-4, (idx.size, 3)) + bias)
    R_att = (turn * Rotation.from_matrix(R_cmd)).as_matrix()
    d = distance_characteristics(
        p_att, p_cmd, idx, cyc, POINT_LABELS, R_attained=R_att, R_command=R_cmd
    )
    assert d is not None and d.ad_abc is not None and d.rd_abc is not None
    r2 = [i for i in range(len(idx)) if idx[i] == 1]
    r4 = [i for i in range(len(idx)) if idx[i] == 3]
    e_att = Rotation.from_matrix(R_att).as_euler("xyz")
    for j in range(3):
        diffs = [e_att[a, j] - e_att[b, j] for a, b in zip(r2, r4, strict=True)]
        diffs = [(v + np.pi) % (2 * np.pi) - np.pi for v in diffs]
        cmd = (cmd_abc[1, j] - cmd_abc[3, j] + np.pi) % (2 * np.pi) - np.pi
        ad, rd = standard_orientation(diffs, cmd)
        assert d.ad_abc[j] == pytest.approx(ad, abs=1e-12)
        assert d.rd_abc[j] == pytest.approx(rd, rel=1e-9)
    # the noise's spread: RD_a ~ 3 sqrt(2) x its per-angle std (two poses per cycle)
    assert np.all(d.rd_abc < 3 * math.sqrt(2) * 2e-4 * 2)
    # position data only: no orientation figures; one of the two: an error
    assert distance_characteristics(p_att, p_cmd, idx, cyc, POINT_LABELS).ad_abc is None
    with pytest.raises(ValueError, match="both"):
        distance_characteristics(p_att, p_cmd, idx, cyc, POINT_LABELS, R_attained=R_att)
