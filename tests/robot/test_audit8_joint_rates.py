"""Audit 8: a robot file's joint ``velocity`` and ``effort`` are bounded to what a joint
can have (1e30 was accepted, and written back into every robot.yaml kinecal wrote); a
URDF's out-of-range ``<limit>`` values are read as unknown."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from kinecal.errors import ConfigError
from kinecal.robot import dump_robot, robot_from_dict, robot_from_urdf
from tests.robot.test_schema import GOOD
from tests.robot.test_urdf_import import GENERAL


def _with(joint: int, units: dict[str, str] | None = None, **kw: object) -> dict:
    d = copy.deepcopy(GOOD)
    if units:  # the same robot in metres and radians
        d["units"] = units
        for j in d["joints"]:
            j.update({k: j[k] / 1e3 for k in ("d", "a")})
            j.update({k: np.radians(j[k]) for k in ("theta_offset", "alpha")})
            j.pop("limits", None)
    d["joints"][joint].update(kw)
    return d


@pytest.mark.parametrize(
    ("joint", "kw", "units", "match"),
    [
        (0, {"velocity": 1e30}, None, r"joints\[0\]\.velocity: 1e\+30 deg/s; expected "
         r"a joint speed greater than 0 and at most 7200 deg/s \(20 turns a second\)"),
        (2, {"velocity": -5.0}, None, r"joints\[2\]\.velocity: -5 deg/s; expected"),
        (1, {"effort": 1e30}, None, r"joints\[1\]\.effort: 1e\+30 N m; expected a "
         r"joint effort greater than 0 and at most 1e\+06 N m \(a torque\)"),
        (4, {"effort": 0}, None, r"joints\[4\]\.effort: 0 N m; expected"),
        (3, {"effort": float("nan")}, None, r"joints\[3\]\.effort: expected a finite"),
        (0, {"velocity": 200.0}, {"length": "m", "angle": "rad"},
         r"joints\[0\]\.velocity: 200 rad/s; expected .* at most 125\.664 rad/s"),
        (1, {"type": "prismatic", "velocity": 30000.0}, None,
         r"joints\[1\]\.velocity: 30000 mm/s; expected .* at most 20000 mm/s\."),
    ],
)  # fmt: skip
def test_out_of_range_rates_are_refused(joint, kw, units, match):
    with pytest.raises(ConfigError, match=match):
        robot_from_dict(_with(joint, units, **kw), "r.yaml")


def test_plausible_rates_load_and_round_trip():
    """The bounds' edges load; a slow joint's speed is not rounded to 0 in the dump
    (it was written to 9 decimals: 1e-10 deg/s became 0, which the file then refused)."""
    d = _with(0, velocity=7200.0, effort=1e6)
    d["joints"][5].update(velocity=1e-10)
    robot = robot_from_dict(d, "r.yaml")
    assert robot.joints[0].velocity == pytest.approx(40 * np.pi)
    again = robot_from_dict(dump_robot(robot), "again")
    for a, b in zip(robot.joints, again.joints):
        assert (a.velocity is None) == (b.velocity is None)
        assert (a.effort is None) == (b.effort is None)
        if a.velocity is not None:
            assert b.velocity == pytest.approx(a.velocity, rel=1e-11)
    assert again.joints[5].velocity > 0


def test_a_urdf_unlimited_rate_is_unknown(tmp_path):
    """A URDF with velocity="1e30" (unlimited): imported as unknown, not kept (the
    robot.yaml written from it was then refused by every command)."""
    text = GENERAL.replace(
        'effort="1" velocity="1"', 'effort="1e30" velocity="1e30"', 1
    )
    assert text != GENERAL
    f = tmp_path / "odd.urdf"
    f.write_text(text)
    robot = robot_from_urdf(f)
    assert robot.joints[0].velocity is None and robot.joints[0].effort is None
    assert robot.joints[2].velocity == pytest.approx(1.0)
    robot_from_dict(dump_robot(robot), "dumped")  # loads back


def test_a_coupling_factor_no_arm_has_is_named():
    """1e30 was refused as a 'singular' coupling, naming no entry and no range."""
    d = copy.deepcopy(GOOD)
    d["coupling"] = [{"joint": 3, "from": 2, "factor": 1}, {"joint": 4, "from": 3,
                     "factor": 1e30}]  # fmt: skip
    with pytest.raises(ConfigError, match=r"coupling\[1\]\.factor: 1e\+30; expected a "
                       r"coupling factor within ±100"):  # fmt: skip
        robot_from_dict(d, "r.yaml")
    d["coupling"][1]["factor"] = -0.5
    assert robot_from_dict(d, "r.yaml").coupling[3, 2] == -0.5
