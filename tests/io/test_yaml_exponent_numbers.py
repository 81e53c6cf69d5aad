"""Numbers in exponent notation in the YAML files a user writes (robot files, frames
files, model files): YAML 1.2 numbers. PyYAML reads YAML 1.1, where ``1e-3`` is a
string (a float needs a dot and a signed exponent), and the robot file's own documented
example ``priors: {load_compliance: 1e-3}`` was refused ("expected a number; got
'1e-3'")."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
import yaml as pyyaml

from kinecal import _yaml
from kinecal.robot import load_robot_file, robot_from_dict

ROBOT = """\
name: exponents
convention: dh
units: {length: mm, angle: deg}
joints:
  - {theta_offset: 0, d: 330, a: 50, alpha: -90, limits: [-170, 170]}
  - {theta_offset: -90, d: 0, a: 330, alpha: 0, limits: [-100, 145]}
  - {theta_offset: 0, d: 0, a: 35, alpha: -90, limits: [-70, 190]}
  - {theta_offset: 0, d: 3.35e2, a: 0, alpha: 90, limits: [-190, 190]}
  - {theta_offset: 0, d: 0, a: 0, alpha: -90, limits: [-125, 125]}
  - {theta_offset: 0, d: 8E1, a: 0, alpha: 0, limits: [-360, 360]}
coupling: [{joint: 3, from: 2, factor: 1e0}]
tool: {x: 0, y: 0, z: 1e2, r: 0, w: 0, p: 0}
gravity: [0, 0, -9.81]
priors: {load_compliance: 1e-3, joint_length: 1, joint_angle: 1e-1}
"""


@pytest.mark.parametrize(
    "text, value",
    [
        ("1e-3", 1e-3),
        ("2E5", 2e5),
        ("1.5e3", 1.5e3),
        ("-3e+2", -300.0),
        (".5e2", 50.0),
        ("1.0e-05", 1e-5),  # YAML 1.1's own form, as PyYAML writes floats
        ("12", 12),
        ("1.5", 1.5),
    ],
)
def test_exponent_numbers_are_numbers(text, value):
    got = _yaml.load(f"a: {text}\n")["a"]
    assert type(got) is type(value) and math.isclose(got, value)


@pytest.mark.parametrize("text", ["1e", "e5", "abc1e3", "1e3x", "'1e3'"])
def test_strings_stay_strings(text):
    assert isinstance(_yaml.load(f"a: {text}\n")["a"], str)


def test_pyyaml_itself_is_left_as_it_is():
    assert pyyaml.safe_load("a: 1e-3") == {"a": "1e-3"}


def test_robot_file_with_exponent_numbers(tmp_path):
    f = tmp_path / "robot.yaml"
    f.write_text(ROBOT)
    robot = load_robot_file(f)
    plain = robot_from_dict(
        _yaml.load(
            ROBOT.replace("3.35e2", "335")
            .replace("8E1", "80")
            .replace("1e0", "1")
            .replace("1e2", "100")
        ),
        source="plain",
    )
    assert robot.joints[3].d == pytest.approx(0.335) and robot.joints[5].d == 0.08
    assert robot.prior_sigma == plain.prior_sigma
    assert (robot.coupling == plain.coupling).all()
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "kinecal",
            "fk",
            "--robot",
            str(f),
            *["0"] * 6,
            "--json",
        ],
        capture_output=True,
        text=True,
    )
    assert out.returncode == 0, out.stderr


def test_strings_of_that_form_are_written_quoted_and_read_back():
    doc = {"label": "12e5", "sha": "1234e5678", "x": 1e-5}
    text = _yaml.dump(doc)
    assert "'12e5'" in text and "'1234e5678'" in text
    assert _yaml.load(text) == doc


def test_model_files_keep_yaml_1_1_numbers():
    """kinecal wrote a 16-digit fingerprint such as 1234e5678... plain before it quoted
    such strings: its own files are read as they were written."""
    assert _yaml.load("robot_sha256: 1234e56789012345\n", exponents=False) == {
        "robot_sha256": "1234e56789012345"
    }
