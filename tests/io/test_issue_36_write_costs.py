"""Issue 36: what ``kinecal calibrate`` writes costs no work done twice."""

from __future__ import annotations

import dataclasses

import numpy as np

from kinecal.io import _model_bounds, _model_file, load_model
from kinecal.io._model_file import save_model_as_read
from kinecal.simulation import LaserTracker, experiment2


def test_issue_36_model_yaml_dumps_its_robot_once(tmp_path, monkeypatch):
    """The robot section is dumped once for the file and its fingerprint, and the
    robot read back is dumped again only when the file's fingerprint does not match
    its section (it was dumped three times)."""
    from kinecal.identification import calibrate

    exp = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=3)
    cal = calibrate(exp.truth.robot, exp.train, "kinematic").calibrated
    cal = dataclasses.replace(cal, info={**cal.info, "source": "train.csv"})
    dumps: list[int] = []
    for mod in (_model_file, _model_bounds):
        f = mod.dump_robot
        monkeypatch.setattr(
            mod, "dump_robot", lambda r, f=f: dumps.append(1) or f(r), raising=True
        )
    path, read = save_model_as_read(tmp_path / "model.yaml", cal)
    assert len(dumps) == 1
    assert read is not None and np.array_equal(read.params, load_model(path).params)
