"""Issue 20 (points 1-2): new sessions with pose data (a turned probe), and folds that
keep poses, sets and the user's groups whole."""

from __future__ import annotations

import copy
import json
from dataclasses import replace

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.geometry import euler_zyx_to_matrix, so3_exp
from kinecal.identification import (
    Measurements,
    calibrate,
    cross_validate,
    evaluate,
    make_folds,
    refit,
)
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, PoseTracker, experiment2, random_truth

ROBOT = load_robot("fanuc-lrmate200id")
OFFSET_DEG = np.array([0.0, 10.0, 0.0, 0.0, -60.0, 0.0])


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


def _pose_data(truth, n, rng):
    q = np.radians(rng.uniform(-50, 50, size=(n, 6)) + OFFSET_DEG)
    p, R = truth.evaluate(q, orientation=True)
    pm, Rm = PoseTracker(30e-6, 3e-4).measure(p, R, rng)
    return Measurements("pose", q, pm, R_user_cam=Rm)


def _turned_probe(truth, angle_deg, axis, centre_flange):
    """The truth with its probe turned about an axis through a point of the flange."""
    model, x = truth.model, truth.params.copy()
    R_c, t_c = model.cam_frames(x)
    turn = so3_exp(np.radians(angle_deg) * np.asarray(axis) / np.linalg.norm(axis))
    x[model.cam_index[0, :3]] = turn @ (t_c[0] - centre_flange) + centre_flange
    R_ref = (turn @ R_c[0]) @ euler_zyx_to_matrix(x[model.cam_index[0, 3:]]).T
    out = copy.copy(truth)
    object.__setattr__(out, "model", model.with_references(None, R_ref[None]))
    object.__setattr__(out, "params", x)
    return out


@pytest.fixture(scope="module")
def tmac():
    """A 6-D tracker (T-Mac) calibration, and a later session with the tracker moved and
    the probe turned by 177 deg about an axis 40 mm from the measured point."""
    truth = random_truth(ROBOT, seed=4)
    rng = np.random.default_rng(1)
    cal = calibrate(ROBOT, _pose_data(truth, 150, rng), "full").calibrated
    _, t_c = truth.model.cam_frames(truth.params)
    turned = _turned_probe(truth, 177.0, [0.2, 0.9, 0.1], t_c[0] + [0.04, 0.0, 0.0])
    later = _pose_data(turned, 120, rng)
    R = euler_zyx_to_matrix(np.radians([40.0, 5.0, -3.0]))
    later = replace(
        later, p=later.p @ R.T + [0.5, -0.3, 0.1], R_user_cam=R @ later.R_user_cam
    )
    return cal, later


def test_issue_20_refit_user_on_a_turned_probe_warns(tmac):
    cal, later = tmac
    ev = evaluate(cal, later, refit=("user",))
    (d,) = [d for d in ev.diagnostics if d.code == "orientation_offset"]
    assert "--refit user,tool" in d.message
    angle = float(d.message.split("common rotation of ")[1].split(" deg")[0])
    assert 170.0 < angle < 180.0


def test_issue_20_refit_user_tool_scores_positions_as_a_position_only_refit(tmac):
    cal, later = tmac
    ev = evaluate(cal, later, refit=("user", "tool"))
    positions = replace(later, kind="point", R_user_cam=None)
    pos_only = evaluate(cal, positions, refit=("user", "tool")).metrics.rms_mm
    assert ev.metrics.rms_mm <= 1.1 * pos_only
    assert ev.metrics.rms_mm < 0.1  # the model is good to ~0.05 mm here
    assert ev.metrics.rot_rms_deg is not None and ev.metrics.rot_rms_deg < 0.1
    assert not [d for d in ev.diagnostics if d.code == "orientation_offset"]
    assert "rot_rms_deg" in ev.metrics.contract()


def test_issue_20_refit_never_trades_positions_for_orientations(tmac):
    """Same session, probe not turned but orientations given a bias: the positions of
    the refit stay as good as a refit on positions alone."""
    cal, later = tmac
    ev_user_tool = evaluate(cal, later, refit=("user", "tool"))
    bias = so3_exp(np.radians([0.0, 2.0, 0.0]))
    biased = replace(later, R_user_cam=later.R_user_cam @ bias)
    ev = evaluate(cal, biased, refit=("user", "tool"))
    assert ev.metrics.rms_mm <= 1.1 * ev_user_tool.metrics.rms_mm


def test_issue_20_refit_marker_moves_only_the_offsets(tmac):
    cal, later = tmac
    with pytest.warns(UserWarning, match="--refit user,tool"):
        new = refit(cal, later, ("marker",))
    moved = {
        new.model.layout.names[i] for i in np.flatnonzero(new.params != cal.params)
    }
    assert moved and all(n.startswith("cam.") and n[-1] in "xyz" for n in moved)


def _three_markers(seed: int = 0) -> tuple[Measurements, Measurements]:
    """Tracker data with three reflectors measured at every pose (and a held-out set)."""
    e = experiment2(seed, tracker=LaserTracker(5e-6, 0.0))
    truth = e.truth
    offsets = np.array([[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.0, 0.03, 0.01]])

    def measure(meas: Measurements, rng) -> Measurements:
        inputs = meas.model_inputs()
        R_fl, o_fl = truth.model.flange_frames(truth.params, inputs)
        R_b, t_b = truth.model.base_frames(truth.params)
        R_c, t_c = truth.model.cam_frames(truth.params)
        rows, p, mk = [], [], []
        for m, off in enumerate(offsets):
            tip = t_c[0] + R_c[0] @ off
            p_base = o_fl + np.einsum("nij,j->ni", R_fl, tip)
            p.append(p_base @ R_b[0].T + t_b[0] + rng.normal(size=p_base.shape) * 5e-6)
            rows.append(np.arange(meas.n))
            mk.append(np.full(meas.n, m))
        order = np.argsort(
            np.concatenate(rows), kind="stable"
        )  # a pose's rows together
        q = np.repeat(meas.q_ctrl, 3, axis=0)
        return Measurements(
            "point",
            q,
            np.concatenate(p)[order],
            marker_index=np.concatenate(mk)[order],
            marker_labels=("a", "b", "c"),
        )

    rng = np.random.default_rng(seed + 1)
    return measure(e.train, rng), measure(e.test.subset(np.arange(0, 2000, 4)), rng)


def test_issue_20_folds_keep_the_rows_of_a_pose_together():
    train, _ = _three_markers()
    folds = make_folds(train, 6)
    assert folds.unit == "pose"
    key = [tuple(q) for q in train.q_ctrl]
    where = {}
    for f, rows in enumerate(folds.test):
        for r in rows:
            where.setdefault(key[r], set()).add(f)
    assert all(len(v) == 1 for v in where.values())
    assert sum(len(t) for t in folds.test) == train.n


def test_issue_20_pose_folds_are_honest_where_row_folds_are_optimistic():
    train, test = _three_markers()
    res = calibrate(ROBOT, train, "full")
    held = evaluate(res.calibrated, test).metrics.rms_mm
    by_pose = cross_validate(ROBOT, train, "full", k=6).rms_mm
    by_row = cross_validate(ROBOT, train, "full", k=6, groups=np.arange(train.n)).rms_mm
    assert abs(by_pose - held) / held < abs(by_row - held) / held
    assert by_row < by_pose


def test_issue_20_a_marker_with_fewer_rows_than_folds_stays_in_training():
    """Two single-row markers (a reflector measured once each): they stay in every
    training set, and the cross-validated error is the one of the other rows, not the
    error of predicting an unknown tool offset."""
    e = experiment2(3, tracker=LaserTracker(5e-6, 0.0))
    meas = e.train
    marker = np.zeros(meas.n, np.intp)
    marker[[10, 40]] = [1, 2]
    p = meas.p.copy()
    p[10] += [0.05, 0.0, 0.0]  # other reflectors, 50 mm away
    p[40] += [0.0, 0.05, 0.0]
    odd = replace(meas, p=p, marker_index=marker, marker_labels=("", "x", "y"))
    folds = make_folds(odd, 5)
    assert folds.always_train[[10, 40]].all()
    assert all(10 not in t and 40 not in t for t in folds.test)
    assert len(folds.notes) == 2 and "marker x has 1 rows" in folds.notes[0]
    cv = cross_validate(ROBOT, odd, "kinematic", k=5)
    plain = cross_validate(ROBOT, meas, "kinematic", k=5)
    assert cv.rms_mm < 1.3 * plain.rms_mm
    assert cv.notes == folds.notes


def test_issue_20_more_folds_than_poses_is_a_clear_error():
    e = experiment2(3)
    small = e.train.subset(np.arange(4))
    with pytest.raises(DataError, match="needs at least 5 poses"):
        make_folds(small, 5)


def test_issue_20_cv_groups_and_refit_on_the_command_line(
    run_cli, simulated_exp2, tmp_path
):
    d = simulated_exp2  # kinecal simulate --experiment 2
    lines = (d / "train.csv").read_text().splitlines()
    lines = [lines[0] + ",station"] + [
        f"{ln},s{i // 20}" for i, ln in enumerate(lines[1:])
    ]
    data = tmp_path / "train_groups.csv"
    data.write_text("\n".join(lines) + "\n")
    out = tmp_path / "cal"
    res = run_cli(
        "calibrate",
        str(data),
        "--robot",
        "fanuc-lrmate200id",
        "--model",
        "kinematic",
        "--out",
        str(out),
        "--cv",
        "3",
        "--cv-groups",
        "station",
        "--no-report",
        "-q",
    )
    assert res.returncode == 0, res.stderr
    cv = json.loads((out / "report.json").read_text())["cross_validation"]
    assert cv["unit"] == "station" and len(cv["model"]["fold_rms_mm"]) == 3
    bad = run_cli(
        "calibrate",
        str(data),
        "--robot",
        "fanuc-lrmate200id",
        "--out",
        str(tmp_path / "x"),
        "--cv",
        "3",
        "--cv-groups",
        "stations",
        "-q",
    )
    assert bad.returncode == 2 and "does not have" in bad.stderr
    ev = run_cli(
        "evaluate",
        str(d / "test.csv"),
        "--model",
        str(out / "model.yaml"),
        "--refit",
        "user,tool",
        "--json",
    )
    assert ev.returncode == 0, ev.stderr
    assert json.loads(ev.stdout)["rms_mm"] < 0.1
    wrong = run_cli(
        "evaluate",
        str(d / "test.csv"),
        "--model",
        str(out / "model.yaml"),
        "--refit",
        "usr",
    )
    assert wrong.returncode == 2 and "--refit" in wrong.stderr
