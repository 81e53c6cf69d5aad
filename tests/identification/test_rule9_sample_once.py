"""``--model auto`` and ``--cv`` together on a large set: the random sample of whole
poses (and its pose groups, on every row) is drawn once, by the selection, and
``--cv`` scores on it (the same sample it would draw: ``sample_rows`` is
deterministic in the seed)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from kinecal.identification import held_out_accuracy, select_model
from kinecal.identification.selection import _crossval
from kinecal.robot import load_robot
from kinecal.simulation import LaserTracker, robot_experiment, robot_truth

ROBOT = load_robot("fanuc-lrmate200id")


def test_auto_and_cv_draw_the_sample_once(monkeypatch):
    truth = robot_truth(ROBOT, seed=4)
    e = robot_experiment(truth, 4, n_train=300, n_test=1, tracker=LaserTracker(5e-6, 0))
    sessions = replace(
        e.train, set_index=np.repeat(np.arange(3), 100), set_labels=("a", "b", "c")
    )
    monkeypatch.setattr(_crossval, "CV_MAX_ROWS", 200)
    calls = []
    real = _crossval.sample_rows

    def spy(meas, groups, seed):
        calls.append(meas.n)
        return real(meas, groups, seed)

    monkeypatch.setattr(_crossval, "sample_rows", spy)
    sel = select_model(ROBOT, sessions, k=3)
    assert calls == [sessions.n]
    held = held_out_accuracy(ROBOT, sessions, sel.spec, 3, selection=sel)
    assert calls == [sessions.n]  # not drawn again
    n_sample = sum(t.size for t in sel.fold_sets.test)
    for fig in held.figures:  # the selection's sample, and the notes say so
        assert sum(t.size for t in fig.folds.test) == n_sample
        assert any(
            f"on {n_sample} of the {sessions.n} rows" in n for n in fig.folds.notes
        )
