"""Audit 8: a path inside a model file (``info.source``, the data it was calibrated on)
is relative to the model file's folder, written and read (it was written as typed and
read from whatever folder a later command ran in: another folder's file of that name was
taken as the calibration data, or the data was not found)."""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

from kinecal.io import load_model, save_model
from kinecal.workflows._export import _loss_poses


def test_info_source_is_relative_to_the_model_file(data, tmp_path, monkeypatch):
    proj = tmp_path / "proj"
    (proj / "sim").mkdir(parents=True)
    (proj / "cal").mkdir()
    shutil.copy(data["train"], proj / "sim" / "train.csv")
    cal = load_model(data["model"])
    monkeypatch.chdir(proj)  # calibrate records the data's path as typed here
    save_model(Path("cal/model.yaml"), replace(cal, info={"source": "sim/train.csv"}))
    text = (proj / "cal" / "model.yaml").read_text()
    assert "source: ../sim/train.csv" in text
    # read from another folder that has a file of the same name: the model's data
    other = tmp_path / "other"
    (other / "sim").mkdir(parents=True)
    (other / "sim" / "train.csv").write_text("j1_deg\n0\n")
    monkeypatch.chdir(other)
    back = load_model(proj / "cal" / "model.yaml")
    assert back.info["source"] == str(proj / "sim" / "train.csv")
    _, where, lines = _loss_poses(back, None, None)
    assert where.endswith("poses of train.csv") and lines, where
    # saved again elsewhere: the same file (the path as read is absolute)
    save_model(other / "again.yaml", back)
    assert load_model(other / "again.yaml").info["source"] == back.info["source"]
    # a path that names no file beside the model (a file written before this rule,
    # relative to its run's folder) is a label: no file is read from it
    (proj / "cal" / "old.yaml").write_text(
        text.replace("source: ../sim/train.csv", "source: sim/train.csv")
    )
    monkeypatch.chdir(proj)
    old = load_model(proj / "cal" / "old.yaml")
    assert old.info["source"] == "sim/train.csv"
    assert "random poses" in _loss_poses(old, None, None)[1]


def test_an_absolute_source_stays_absolute(data, tmp_path):
    cal = load_model(data["model"])
    src = str(data["train"].resolve())
    save_model(tmp_path / "m.yaml", replace(cal, info={"source": src}))
    assert load_model(tmp_path / "m.yaml").info["source"] == src
