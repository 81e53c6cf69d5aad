"""Audit 9: a robot or model YAML beyond any kinecal writes is refused by its size
before it is parsed (3.4 MB of YAML took 6.5 s to read, 200 MB minutes and GBs)."""

from __future__ import annotations

from pathlib import Path

import pytest

from kinecal.errors import ConfigError
from kinecal.io import load_model
from kinecal.robot import load_robot
from kinecal.robot._robot_file import MAX_TEXT_BYTES


def test_yaml_files_beyond_the_size_bound(tmp_path, monkeypatch):
    robot = tmp_path / "robot.yaml"
    robot.write_text("name: x\n" + "# padding\n" * 200_000)  # 2 MB
    monkeypatch.setattr("kinecal.robot._robot_file.MAX_TEXT_BYTES", 1 << 20)
    with pytest.raises(ConfigError, match=r"robot.yaml: 1.9 MB; expected a robot YAML"):
        load_robot(robot)
    model = tmp_path / "model.yaml"
    model.write_bytes(robot.read_bytes())
    with pytest.raises(ConfigError, match=r"model.yaml: 1.9 MB; expected a model.yaml"):
        load_model(model)
    assert MAX_TEXT_BYTES >= 4 << 20  # far above any file kinecal writes


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_a_device_without_end(capsys):
    """--robot /dev/zero read until the memory was full (exit 5, or the machine's)."""
    from tests.cli_contract import failed_with, run_kinecal

    for args in (
        ("fk", "--robot", "/dev/zero", "0", "0", "0", "0", "0", "0"),
        ("fk", "--model", "/dev/zero", "--", "0", "0", "0", "0", "0", "0"),
        ("import-urdf", "/dev/zero", "--out", "/nonexistent/r.yaml"),
    ):
        failed_with(run_kinecal(capsys, *args), "/dev/zero: more than", "(a device")


def test_a_model_argument_that_is_another_file_says_what_it_is(tmp_path):
    from kinecal import _yaml as yaml
    from kinecal.robot import dump_robot

    cases = {
        "robot.yaml": (
            yaml.dump(dump_robot(load_robot("fanuc-lrmate200id"))),
            "it is a robot file: calibrate with it",
        ),
        "arm.urdf": ('<?xml version="1.0"?>\n<robot name="a"/>\n', "an XML document"),
        "data.csv": ("x_mm,y_mm,z_mm,j1_deg\n1,2,3,4\n", "it is a CSV table"),
        "report.json": (
            '{"kinecal_version": "0.1.0", "data": {}}',
            "it is a calibration's report.json",
        ),
    }
    for name, (text, needle) in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(ConfigError, match="no 'kinecal_model' key") as exc:
            load_model(tmp_path / name)
        assert needle in str(exc.value), str(exc.value)
