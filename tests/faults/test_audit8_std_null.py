"""Audit 8: an estimated parameter with ``std: null`` (no standard deviation: the fit's
normal matrix could not be inverted). kinecal wrote 0 there, a claim of an exact value
(every change then 'significant' in report --compare); it now writes null, and every
command reads such a file: the value without an uncertainty."""

from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np

from kinecal.io import load_model, read_measurements, save_model
from tests.cli_contract import run_kinecal


def test_a_fit_without_covariance_writes_null(data, tmp_path, monkeypatch):
    import kinecal.identification._uncertainty as unc
    from kinecal.identification import calibrate

    robot = load_model(data["model"]).model.robot
    meas = read_measurements(data["train"], robot)

    def singular(*args, **kwargs):
        raise np.linalg.LinAlgError("singular")

    monkeypatch.setattr(unc, "psd_inverse", singular)
    res = calibrate(robot, meas, "kinematic")
    cal = res.calibrated
    est = np.array([s == "estimated" for s in cal.status])
    assert est.any() and np.isnan(cal.std[est]).all(), cal.std[est]
    save_model(tmp_path / "model.yaml", cal)
    back = load_model(tmp_path / "model.yaml")
    assert np.isnan(back.std[est]).all() and list(back.status) == list(cal.status)


def test_every_command_reads_estimated_without_std(data, tmp_path, capsys):
    cal = load_model(data["model"])
    est = np.array([s == "estimated" for s in cal.status])
    d = tmp_path / "nostd"
    d.mkdir()
    model = d / "model.yaml"
    save_model(model, replace(cal, std=np.where(est, np.nan, cal.std)))
    assert "std: null" in model.read_text()
    runs = {
        "evaluate": ("evaluate", data["test"], "--model", model, "--json"),
        "compensate": ("compensate", data["targets"], "--model", model,
                       "--out", tmp_path / "c.csv"),
        "fk": ("fk", "--model", model, "--json", "--", "10", "20", "-10", "5", "-60", "3"),
        "export": ("export-urdf", model, "--out", tmp_path / "m.urdf"),
        "plan": ("plan", "--model", model, "--add", "4", "--noise-mm", "0.01",
                 "--out", tmp_path / "p.csv"),
    }  # fmt: skip
    for name, args in runs.items():
        res = run_kinecal(capsys, *args)
        assert res.code == 0, (name, str(res))
    # plan: no information claimed from standard deviations the file does not hold
    assert "std: null" in res.err, res.err
    old = tmp_path / "old"
    old.mkdir()
    shutil.copy(data["model"], old / "model.yaml")
    # report --compare: the change of a parameter without a std is not judged
    res = run_kinecal(
        capsys, "report", "--compare", old, d, "--out", tmp_path / "c.html"
    )
    assert res.code == 0, str(res)
