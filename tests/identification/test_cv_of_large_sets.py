"""Issue 36: ``--cv`` of a large set cross-validates a random sample of its poses.

The default ``calibrate`` cross-validates (``--cv 5``: ten fold calibrations and the
nominal robot's); on a million rows that took 200 s of CPU and 4 GB where the
calibration itself takes a fraction. Above ``CV_MAX_ROWS`` rows a random sample of whole
poses is cross-validated (every set keeps rows), and the folds' notes say so. On 200 000
twin poses the model's figures equal those of every row to 4 digits (0.018956 /
0.018954 mm against 0.018956 / 0.018956 mm), the nominal robot's to 0.3 %.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from kinecal.geometry import euler_zyx_to_matrix
from kinecal.identification import Measurements, calibrate, held_out_accuracy
from kinecal.identification.selection import _crossval
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, experiment2

ROBOT = load_robot("fanuc-lrmate200id")


@pytest.fixture(scope="module")
def sessions():
    """Three sessions of 120 poses (the tracker moved between them); the third one
    with each pose seen twice (two markers' rows at one pose)."""
    e = experiment2(8, tracker=LaserTracker(5e-6, 0.0))
    parts = []
    for k in range(3):
        m = e.test.subset(np.arange(120 * k, 120 * k + 120))
        R = euler_zyx_to_matrix(np.radians([15.0 * k, 1.0, 0.0]))
        parts.append(replace(m, p=m.p @ R.T + [0.1 * k, 0.0, 0.0]))
    q = np.concatenate([parts[0].q_ctrl, parts[1].q_ctrl, parts[2].q_ctrl[:60]])
    p = np.concatenate([parts[0].p, parts[1].p, parts[2].p[:60]])
    q = np.concatenate([q, parts[2].q_ctrl[:60]])
    p = np.concatenate([p, parts[2].p[:60]])
    sets = np.repeat(np.arange(3), 120)
    return Measurements("point", q, p, set_index=sets, set_labels=("a", "b", "c"))


def test_a_large_set_is_cross_validated_on_a_sample_of_whole_poses(
    sessions, monkeypatch
):
    spec = calibrate(ROBOT, sessions, "kinematic").calibrated.model.spec
    full = held_out_accuracy(ROBOT, sessions, spec, 3)
    assert not any("drawn at random" in n for f in full.figures for n in f.folds.notes)
    assert sum(t.size for t in full.transfer.folds.test) == sessions.n

    monkeypatch.setattr(_crossval, "CV_MAX_ROWS", 200)
    seen = []
    real = _crossval.sample_rows

    def spy(meas, groups, seed):
        out = real(meas, groups, seed)
        seen.append(out[0])
        return out

    monkeypatch.setattr(_crossval, "sample_rows", spy)
    held = held_out_accuracy(ROBOT, sessions, spec, 3)
    (sample,) = seen
    # About CV_MAX_ROWS rows, each set kept, the two rows of a pose kept together.
    assert 150 <= sample.n <= 260 and set(sample.set_index) == {0, 1, 2}
    twice = sample.q_ctrl[sample.set_index == 2]
    keys = [tuple(np.round(r, 9)) for r in twice]
    assert all(keys.count(k) == 2 for k in keys)
    for fig in held.figures:
        assert sum(t.size for t in fig.folds.test) == sample.n
        (note,) = [n for n in fig.folds.notes if "drawn at random" in n]
        assert f"on {sample.n} of the {sessions.n} rows" in note
    # The same figures' kind; the model's held-out RMS near that of every row.
    assert [f.name for f in held.figures] == ["in-session", "new session"]
    assert held.transfer.model.rms_mm == pytest.approx(
        full.transfer.model.rms_mm, rel=0.25
    )


def test_the_sample_keeps_a_small_set_whole(sessions, monkeypatch):
    big = sessions.subset(np.flatnonzero(sessions.set_index < 2))
    small = sessions.subset(np.flatnonzero(sessions.set_index == 2)[:40])
    meas = Measurements(
        "point",
        np.concatenate([big.q_ctrl, small.q_ctrl]),
        np.concatenate([big.p, small.p]),
        set_index=np.concatenate([big.set_index, small.set_index]),
        set_labels=sessions.set_labels,
    )
    monkeypatch.setattr(_crossval, "CV_MAX_ROWS", 60)
    sample, _, _ = _crossval.sample_rows(meas, None, 0)
    assert np.count_nonzero(sample.set_index == 2) == 40  # all of the small set
    assert 50 <= np.count_nonzero(sample.set_index == 0) < 70


def test_auto_chooses_on_the_sample_and_calibrates_on_every_row(sessions, monkeypatch):
    """``--model auto`` on a large set: the candidates are cross-validated on the same
    sample as ``--cv`` (its figures are the table's on the same folds), the choice is
    calibrated on every row (the selection's shared fit is the sample's)."""
    from kinecal.workflows import calibrate_measurements

    monkeypatch.setattr(_crossval, "CV_MAX_ROWS", 200)
    run = calibrate_measurements(ROBOT, sessions, model="auto", cv_folds=3)
    sel = run.selection
    assert sel is not None and sel.calibration(run.options) is None
    assert any("drawn at random" in w for w in sel.warnings)
    n_sample = sum(t.size for t in sel.fold_sets.test)
    assert 150 <= n_sample <= 260
    # The model is the calibration on every row; --cv scored on the sample's folds.
    every = calibrate(ROBOT, sessions, run.spec, run.options).calibrated.params
    np.testing.assert_allclose(run.result.calibrated.params, every, rtol=1e-9)
    new = run.held_out.transfer
    assert sum(t.size for t in new.folds.test) == n_sample
    chosen = next(c for c in sel.candidates if c.chosen)
    assert new.folds.unit == sel.unit == "set"  # the folds auto chose on
    assert new.model.rms_mm == chosen.cv_rms_mm


def test_the_sample_keeps_a_rare_marker(sessions, monkeypatch):
    """A marker seen in a few poses only stays in the sample with its rows (its tool
    offset is fitted on them)."""
    marker = np.zeros(sessions.n, np.intp)
    marker[[5, 77, 151]] = 1
    meas = replace(sessions, marker_index=marker, marker_labels=("m1", "m2"))
    monkeypatch.setattr(_crossval, "CV_MAX_ROWS", 60)
    sample, _, _ = _crossval.sample_rows(meas, None, 0)
    assert np.count_nonzero(sample.marker_index == 1) == 3
