"""A robot file whose numbers are all in another unit than its ``units`` say: each
number passed its own check, the robot loaded, and ``simulate``/``plan`` moved every
joint within +-3 deg (limits typed in radians in a degrees file) or ``fk`` put the flange
a millimetre from the base (lengths in metres in an mm file), with exit 0."""

from __future__ import annotations

import re

import pytest

from kinecal.errors import ConfigError
from kinecal.robot import robot_from_dict
from tests.cli_contract import failed_with, run_kinecal

LIMITS_DEG = [
    (-170, 170),
    (-100, 145),
    (-70, 190),
    (-190, 190),
    (-125, 125),
    (-360, 360),
]
ROWS_MM = [(0, 330, 50, -90), (-90, 0, 330, 0), (0, 0, 35, -90), (0, 335, 0, 90),
           (0, 0, 0, -90), (0, 80, 0, 0)]  # fmt: skip


def _doc(limits, rows, tool_z=100.0, length="mm", angle="deg"):
    return {
        "name": "slips",
        "convention": "dh",
        "units": {"length": length, "angle": angle},
        "joints": [
            {"theta_offset": o, "d": d, "a": a, "alpha": al, "limits": list(lim)}
            for (o, d, a, al), lim in zip(rows, limits)
        ],
        "tool": {"z": tool_z},
    }


def test_the_robot_as_typed_loads():
    robot_from_dict(_doc(LIMITS_DEG, ROWS_MM))


def test_limits_in_radians_in_a_degrees_file_are_refused():
    rad = [
        (round(lo * 3.14159 / 180, 2), round(hi * 3.14159 / 180, 2))
        for lo, hi in LIMITS_DEG
    ]
    with pytest.raises(ConfigError, match=r"limits lie within \+-6.28 deg.*radians"):
        robot_from_dict(_doc(rad, ROWS_MM), source="r.yaml")
    # one narrow joint among wide ones is a robot's own choice
    narrow = [(-3, 3), *LIMITS_DEG[1:]]
    robot_from_dict(_doc(narrow, ROWS_MM))


def test_lengths_in_metres_in_an_mm_file_are_refused():
    rows_m = [(o, d / 1e3, a / 1e3, al) for o, d, a, al in ROWS_MM]
    with pytest.raises(ConfigError, match=r"add up to 1.26 mm.*metres"):
        robot_from_dict(_doc(LIMITS_DEG, rows_m, tool_z=0.1), source="r.yaml")
    # the same numbers with units.length: m are the robot
    r = robot_from_dict(_doc(LIMITS_DEG, rows_m, tool_z=0.1, length="m"))
    assert r.joints[0].d == pytest.approx(0.33)


def test_the_command_names_the_file_and_exits_2(tmp_path, capsys):
    import yaml

    rad = [
        (-2.97, 2.97),
        (-1.7, 2.5),
        (-1.2, 3.3),
        (-3.3, 3.3),
        (-2.2, 2.2),
        (-6.28, 6.28),
    ]
    f = tmp_path / "robot.yaml"
    f.write_text(yaml.safe_dump(_doc(rad, ROWS_MM)))
    res = run_kinecal(capsys, "fk", "--robot", f, "0", "0", "0", "0", "0", "0")
    failed_with(res, "robot.yaml", "limits", "radians", "units.angle: rad")
    assert not re.search(r"Traceback", res.err)
