"""Audit 7: robot YAMLs with values that parse but cannot be right. A tool or flange
angle of 1e9 deg (frame0 alone was bounded) and a rated payload of 1e9 kg (it raises
the payload kinecal accepts to 10 x that) loaded without a word."""

from __future__ import annotations

import pytest

from kinecal.errors import ConfigError
from kinecal.robot import load_robot

ROBOT = """name: r
convention: dh
units: {{length: mm, angle: {angle}}}
joints:
  - {{theta_offset: 0, d: 330, a: 50, alpha: -90, limits: [-170, 170]}}
  - {{theta_offset: -90, d: 0, a: 330, alpha: 180, limits: [-100, 145]}}
  - {{theta_offset: 0, d: 0, a: 35, alpha: -90, limits: [-70, 205]}}
  - {{theta_offset: 0, d: -335, a: 0, alpha: 90, limits: [-190, 190]}}
  - {{theta_offset: 180, d: 0, a: 0, alpha: 90, limits: [-125, 125]}}
  - {{theta_offset: 0, d: -80, a: 0, alpha: 0, limits: [-360, 360]}}
"""


def _robot(tmp_path, extra, angle="deg"):
    text = ROBOT.format(angle=angle)
    if angle == "rad":  # the limits and angles in radians
        for deg in ("-170, 170", "-100, 145", "-70, 205", "-190, 190", "-125, 125",
                    "-360, 360", "alpha: -90", "alpha: 180", "alpha: 90",
                    "theta_offset: -90", "theta_offset: 180"):  # fmt: skip
            head, _, nums = deg.rpartition(": ")
            rad = ", ".join(f"{float(x) * 3.141592653589793 / 180:.6f}"
                            for x in nums.split(", "))  # fmt: skip
            text = text.replace(deg, f"{head}: {rad}" if head else rad)
    f = tmp_path / "robot.yaml"
    f.write_text(text + extra)
    return f


@pytest.mark.parametrize(
    "extra, angle, needles",
    [
        ("tool: {x: 0, y: 0, z: 100, r: 1e9, w: 0, p: 0}\n", "deg",
         ["tool.r", "1e+09 deg", "over 2 turns"]),
        ("flange: {x: 0, y: 0, z: 0, r: 0, w: 900, p: 0}\n", "deg",
         ["flange.w", "900 deg", "over 2 turns"]),
        ("tool: {x: 0, y: 0, z: 100, r: 90, w: 0, p: 0}\n", "rad",
         ["tool.r", "90 rad", "did you mean 'deg'?"]),
        ("rated_payload_kg: 1e9\n", "deg",
         ["rated_payload_kg", "up to 10000 kg", "1e+09"]),
        ("payload_kg: 5e4\n", "deg", ["payload_kg", "up to 10000 kg", "50000"]),
    ],
)  # fmt: skip
def test_values_that_cannot_be_right_are_refused(tmp_path, extra, angle, needles):
    f = _robot(tmp_path, extra, angle)
    with pytest.raises(ConfigError) as err:
        load_robot(f)
    for n in [str(f), *needles]:
        assert n in str(err.value), str(err.value)


@pytest.mark.parametrize(
    "extra",
    [
        "tool: {x: 0, y: 0, z: 100, r: -180, w: 90, p: 720}\n",
        "rated_payload_kg: 2300\n",  # the heaviest industrial robots
    ],
)
def test_plausible_values_still_load(tmp_path, extra):
    assert load_robot(_robot(tmp_path, extra)).n_joints == 6
