"""Issue 26: large data by blocks of poses. The Jacobian of more than BLOCK_ROWS residual
rows is never held; every product the identification takes of it (normal equations,
variance components, leave-one-out errors, identifiability) comes from blocks, with the
numbers of the whole Jacobian to rounding. Here the block size is made tiny, so that
data of a hundred poses take the path of a million."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.identification import (
    Measurements,
    Weights,
    analyse_identifiability,
    calibrate,
    residuals,
)
from kinecal.identification._identifiability import identifiability_from_normal
from kinecal.measurement import _blocks
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import load_robot
from kinecal.simulation import PoseTracker, random_truth

ROBOT = load_robot("fanuc-lrmate200id")


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of 61 residual rows: 20 poses of point data, 10 of pose data."""
    monkeypatch.setattr(_blocks, "BLOCK_ROWS", 61)


def _same_calibration(a, b):
    z = (a.params - b.params) / np.where(a.std > 0, a.std, 1.0)
    assert np.nanmax(np.abs(z)) < 1e-6, np.nanmax(np.abs(z))
    assert a.calibrated.status == b.calibrated.status
    np.testing.assert_allclose(b.std, a.std, rtol=1e-6)
    assert [s.name for s in a.stages] == [s.name for s in b.stages]
    assert [d.code for d in a.diagnostics] == [d.code for d in b.diagnostics]
    assert [o.row for o in a.rejected] == [o.row for o in b.rejected]
    assert a.metrics_after.rms_mm == pytest.approx(b.metrics_after.rms_mm, rel=1e-9)


def test_issue_26_point_data_by_blocks_equal_the_whole_jacobian(
    exp2_exact, monkeypatch
):
    meas = exp2_exact.train
    whole = calibrate(exp2_exact.truth.robot, meas, "full")
    monkeypatch.setattr(_blocks, "BLOCK_ROWS", 61)
    blocks = calibrate(exp2_exact.truth.robot, meas, "full")
    _same_calibration(whole, blocks)


def test_issue_26_pose_data_by_blocks_equal_the_whole_jacobian(monkeypatch):
    """Pose data without sigmas: the noise from the residuals (Helmert, per marker and
    per kind), the orientation weight by leave-one-out errors, the sandwich covariance."""
    truth = random_truth(ROBOT, seed=10)
    rng = np.random.default_rng(11)
    q = np.radians(
        rng.uniform(-50, 50, size=(150, 6)) + np.array([0, 10, 0, 0, -60, 0])
    )
    p, R = truth.evaluate(q, orientation=True)
    assert R is not None
    pm, Rm = PoseTracker(30e-6, 3e-4).measure(p, R, rng)
    meas = Measurements(
        "pose",
        q,
        pm,
        R_user_cam=Rm,
        set_index=(np.arange(150) >= 70).astype(np.intp),
        set_labels=("a", "b"),
    )
    whole = calibrate(ROBOT, meas, "full")
    monkeypatch.setattr(_blocks, "BLOCK_ROWS", 61)
    blocks = calibrate(ROBOT, meas, "full")
    _same_calibration(whole, blocks)
    np.testing.assert_allclose(blocks.weights.sigma, whole.weights.sigma, rtol=1e-8)


def test_issue_26_the_jacobian_of_large_data_is_not_held(exp2_exact, small_blocks):
    meas = exp2_exact.train
    cm = CalibrationModel(exp2_exact.truth.robot, ModelSpec.preset("full"))
    x = cm.nominal + 1e-4 * cm.layout.scales
    w = Weights.default(meas)
    blk = residuals(cm, x, meas, w, jacobian=True, products=True)
    assert blk.J is None and blk.blocks is not None
    _blocks.BLOCK_ROWS = 10**9  # the same data, held whole
    held = residuals(cm, x, meas, w, jacobian=True, products=True)
    assert held.J is not None
    np.testing.assert_array_equal(blk.r, held.r)
    cols = np.arange(cm.size + len(cm.link_products))
    sc = np.concatenate([cm.layout.scales, np.ones(len(cm.link_products))])
    sw = np.random.default_rng(3).uniform(0.5, 1.0, meas.n)
    for weights in (None, sw):
        A, g = blk.normal(cols, sc, weights)
        A0, g0 = held.normal(cols, sc, weights)
        np.testing.assert_allclose(A, A0, rtol=1e-11, atol=1e-11 * np.abs(A0).max())
        np.testing.assert_allclose(g, g0, rtol=1e-11, atol=1e-11 * np.abs(g0).max())
    # the blocks, in order, are the rows of the whole Jacobian
    stacked = np.concatenate([J for _, J in blk.jacobian_blocks()])
    np.testing.assert_array_equal(stacked, held.J[:, :, : cm.size])


def _identifiability_cases(exp2_exact, exp1_exact):
    """Whitened Jacobians (m, P) at generic points, with known redundancies."""
    from kinecal.identification._stages import _generic_point

    out = []
    for e, kind in ((exp2_exact, "point"), (exp1_exact, "sensor")):
        meas = e.train
        for preset in ("kinematic", "ntm", "rfcm", "full"):
            spec = ModelSpec.preset(
                preset, cam_rotation=kind != "point", has_self_weight=True
            )
            cm = CalibrationModel(e.truth.robot, spec)
            x = _generic_point(cm, cm.nominal)
            blk = residuals(cm, x, meas, Weights.default(meas), jacobian=True)
            assert blk.J is not None
            out.append((cm, blk.J.transpose(2, 1, 0).reshape(cm.size, -1).T))
    return out


def _qr_reference(J, layout, drop_tol=1e-6, weak_tol=1e-3):
    """The analysis by Householder QR of the scaled, normalised columns of J in the
    order of preference (numpy's QR; the partners by least squares on R): an
    independent oracle for the module's Cholesky of the normal matrix."""
    from kinecal.identification import priority_order

    Js = J * layout.scales
    norms = np.linalg.norm(Js, axis=0)
    order = list(priority_order(layout))
    zero = norms[order] <= 1e-12 * norms[order].max()
    Jn = np.where(zero, 0.0, Js[:, order] / np.where(zero, 1.0, norms[order]))
    R = np.linalg.qr(Jn, mode="r")
    fraction = np.full(layout.size, np.nan)
    kept, dropped, weak, partners = [], [], [], {}
    for c, i in enumerate(order):
        f = 0.0 if zero[c] else abs(R[c, c])
        fraction[i] = f
        if f < drop_tol:
            dropped.append(layout.names[i])
            if not zero[c] and kept:
                cols = [order.index(k) for k in kept]
                coef = np.linalg.lstsq(R[:, cols], R[:, c], rcond=None)[0]
                coef = coef * norms[i] / norms[kept]
                top = np.argsort(-np.abs(coef))[:4]
                big = np.abs(coef).max()
                partners[layout.names[i]] = [
                    (layout.names[kept[t]], coef[t])
                    for t in top
                    if abs(coef[t]) > 1e-3 * big
                ]
        else:
            kept.append(i)
            if f < weak_tol:
                weak.append(layout.names[i])
    sv = np.linalg.svd(R[:, [order.index(k) for k in kept]], compute_uv=False)
    free = np.zeros(layout.size, bool)
    free[kept] = True
    return free, dropped, weak, fraction, sv, partners


def test_issue_26_identifiability_from_the_normal_matrix_decides_as_qr_does(
    exp2_exact, exp1_exact
):
    """The Cholesky of the normal matrix in the order of preference drops, keeps and
    flags as weak the same parameters as a Householder QR of the Jacobian, with the same
    partners and singular values to rounding, and the same fractions up to the first
    parameter dropped. After it the QR's are smaller: Householder turns a dropped
    column's remainder (of round-off size, 1e-16) into a unit direction and projects
    every later column on it too, the normal form on the kept columns only."""
    from kinecal.identification import priority_order

    for cm, J in _identifiability_cases(exp2_exact, exp1_exact):
        every = np.ones(cm.size, bool)
        free, dropped, weak, fraction, sv, partners = _qr_reference(J, cm.layout)
        for ne in (
            analyse_identifiability(J, cm.layout, every),
            identifiability_from_normal(J.T @ J, cm.layout, every),
        ):
            assert np.array_equal(free, ne.free), cm.spec.name
            assert dropped == [d.name for d in ne.dropped]
            assert weak == [w for w, _ in ne.weak]
            order = priority_order(cm.layout)
            first = next((k for k, i in enumerate(order) if not free[i]), order.size)
            before, after = order[:first], order[first:]
            np.testing.assert_allclose(ne.fraction[before], fraction[before], rtol=1e-8)
            kept = after[free[after]]
            assert np.all(ne.fraction[kept] >= fraction[kept] * (1 - 1e-8))
            np.testing.assert_allclose(ne.singular_values, sv, rtol=1e-6)
            for d in ne.dropped:
                want = partners.get(d.name, [])
                assert [n for n, _ in d.partners] == [n for n, _ in want]
                np.testing.assert_allclose(
                    [c for _, c in d.partners], [c for _, c in want], rtol=1e-5
                )


def test_issue_26_a_large_calibration_reports_its_progress(
    exp2_exact, small_blocks, monkeypatch
):
    """Long stages report how they get on (here at every chance): solver iterations and
    passes over the poses, with the time left in the pass."""
    from kinecal.identification import _problem

    monkeypatch.setattr(_problem, "REPORT_EVERY", 0.0)
    lines = []
    calibrate(
        exp2_exact.truth.robot,
        exp2_exact.train,
        "kinematic",
        progress=lambda stage, detail: lines.append((stage, detail)),
    )
    assert any(d.startswith("iteration 2, cost") for _, d in lines), lines
    assert any("of 100 poses" in d and "s left in this pass" in d for _, d in lines)


def test_issue_26_flange_frames_of_large_data_from_the_tool_pose(
    exp1_exact, small_blocks
):
    """The closed-form start takes the flange frames of large data by blocks, from the
    model's tool pose (compiled kernel) with the user frame at the identity: equal to the
    model's own flange frames to rounding, compliance and cam frames included."""
    from kinecal.identification._init import _flange
    from kinecal.identification._problem import Problem

    meas = exp1_exact.train  # sensor data: a point in the cam frame on every row
    problem = Problem.make(exp1_exact.truth.robot, meas, "full")
    cm = problem.model
    x = cm.nominal + 1e-3 * cm.layout.scales  # compliance on, frames off the identity
    R, o = _flange(cm, x, meas)
    R0, o0 = cm.flange_frames(x, meas.model_inputs())
    np.testing.assert_allclose(R, R0, rtol=0, atol=1e-14)
    np.testing.assert_allclose(o, o0, rtol=0, atol=1e-14)
