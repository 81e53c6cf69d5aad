"""Issue 33, end to end: a 7-axis arm imported from its URDF (with inertials), poses from
`kinecal plan`, data from an independent simulator with gravity deflection
(tests/independent_arm.py). The default calibration of the imported file is within 1.2x
of the same model with the self-weight layout set by hand; ``--model auto`` as well."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from kinecal import _yaml as yaml
from kinecal.identification import Measurements
from kinecal.io import write_measurements
from kinecal.robot import load_robot_file
from tests.independent_arm import random_poses, true_arm, urdf_text


def _joints(path) -> np.ndarray:
    """The j1_deg.. columns of a plan (rad)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    cols = [
        i for i, h in enumerate(rows[0]) if h.startswith("j") and h.endswith("_deg")
    ]
    return np.radians(np.array([[float(r[i]) for i in cols] for r in rows[1:]]))


def _cli(capsys, *args: str, err: list | None = None) -> str:
    from kinecal.cli import main

    code = main(list(args))
    out = capsys.readouterr()
    assert code == 0, out.err
    if err is not None:
        err.append(out.err)
    return out.out


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    d = tmp_path_factory.mktemp("arm7")
    (d / "arm7.urdf").write_text(urdf_text())
    return d


def _rms(capsys, d, model: str) -> float:
    out = _cli(capsys, "evaluate", str(d / "test.csv"), "--model", model, "--json")
    return float(json.loads(out)["rms_mm"])


@pytest.mark.slow  # 1.4-4.3 s: in test-slow, to keep make test within its budget
def test_default_calibration_of_imported_urdf_as_good_as_hand_layout(results, capsys):
    d = results
    _cli(
        capsys,
        "import-urdf",
        str(d / "arm7.urdf"),
        "--tip",
        "flange",
        "--out",
        str(d / "arm7.yaml"),
    )
    robot = load_robot_file(d / "arm7.yaml")
    assert robot.link_bodies == (2, 3, 4, 5, 6, 7)  # J1 vertical: body 1 unfelt
    _cli(
        capsys,
        "plan",
        "--robot",
        str(d / "arm7.yaml"),
        "--poses",
        "60",
        "--n-candidates",
        "800",
        "--tool",
        "30,0,60",
        "--out",
        str(d / "plan.csv"),
    )
    truth = true_arm(0)
    rng = np.random.default_rng(1)
    q_train = _joints(d / "plan.csv")
    q_test = random_poses(300, rng)
    for name, q in (("train", q_train), ("test", q_test)):
        meas = Measurements("point", q, truth.measure(q, rng), source=name)
        write_measurements(d / f"{name}.csv", meas, robot)
    # The same model with the lumped layout set by hand (shoulder J2, elbow J4).
    doc = yaml.load((d / "arm7.yaml").read_text())
    doc.pop("link_masses")
    doc["self_weight"] = {"shoulder": 2, "elbow": 4, "wrist_frame": 5}
    (d / "hand.yaml").write_text(yaml.dump(doc))
    # And with no self-weight layout at all (the masses dropped).
    doc["self_weight"] = None
    (d / "none.yaml").write_text(yaml.dump(doc))
    rms, err = {}, {}
    for label, robot_file, model in (
        ("default", "arm7.yaml", "full"),
        ("hand", "hand.yaml", "full"),
        ("auto", "arm7.yaml", "auto"),
        ("kinematic", "arm7.yaml", "kinematic"),
        ("none", "none.yaml", "full"),
    ):
        out = d / label
        args = ["calibrate", str(d / "train.csv"), "--robot", str(d / robot_file)]
        err[label] = []
        _cli(
            capsys,
            *args,
            "--model",
            model,
            "--out",
            str(out),
            "-q",
            "--no-report",
            err=err[label],
        )
        rms[label] = _rms(capsys, d, str(out / "model.yaml"))
    print(rms)
    # Only the robot without a layout is told its residuals look like gravity.
    assert "no self-weight layout" in err["none"][0]
    assert rms["none"] > 1.5 * rms["default"]
    for label in ("default", "hand", "auto", "kinematic"):
        assert "no self-weight layout" not in err[label][0]
    assert rms["kinematic"] > 3 * rms["default"]  # the gravity deflection is there
    assert rms["default"] <= 1.2 * rms["hand"]
    assert rms["auto"] <= 1.2 * rms["hand"]
    assert rms["default"] <= 0.080 and rms["auto"] <= 0.080
