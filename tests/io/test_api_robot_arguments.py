"""A script hands the readers and :func:`kinecal.identification.calibrate` a robot
name, a path or a dict where objects are expected: an ``AttributeError`` deep inside
before ('str' object has no attribute 'n_joints'), now a ConfigError (a ValueError)
naming the argument and where one comes from."""

from __future__ import annotations

from pathlib import Path

import pytest

from kinecal.errors import ConfigError
from kinecal.identification import calibrate
from kinecal.io import read_compensation_targets, read_data, read_measurements
from kinecal.robot import load_robot

UR10 = Path(__file__).resolve().parents[1] / "data" / "real" / "ur10_mocap.csv"


@pytest.mark.parametrize(
    "reader", [read_measurements, read_data, read_compensation_targets]
)
def test_readers_want_a_robot_description(reader):
    with pytest.raises(
        ConfigError,
        match=r"robot: expected a RobotDescription .*load_robot.*got str 'ur10e'",
    ):
        reader(UR10, "ur10e")


def test_calibrate_names_the_argument_it_cannot_use():
    robot = load_robot("ur10e")
    meas = read_measurements(UR10, robot)
    cases = [
        (("ur10e", meas), {}, r"robot: expected a RobotDescription"),
        ((robot, str(UR10)), {}, r"meas: expected a Measurements .*read_measurements"),
        ((robot, meas, "full", {}), {}, r"options: expected a CalibrationOptions"),
        ((robot, meas, 3), {}, r"model: expected a preset name"),
    ]
    for args, kw, needle in cases:
        with pytest.raises(ConfigError, match=needle):
            calibrate(*args, **kw)
