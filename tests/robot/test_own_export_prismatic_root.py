"""kinecal's own URDF export of a robot whose first joint is prismatic (TIAGo's torso)
is read back as ``--robot``: the base link under the measurement frame ``user`` is found
although a slide's line has no position (it was refused: "the first joint axis must be
the base link's z axis"), and its forward kinematics equal the model's kinematic part."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from kinecal.io import save_model
from kinecal.measurement import CalibratedModel
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import load_robot_file
from tests.cli_contract import run_kinecal

ROOT = Path(__file__).resolve().parents[2]
TIAGO = ROOT / "examples" / "data" / "tiago_figaroh_qualisys" / "tiago.yaml"


@pytest.mark.parametrize("names", [None, "robot"])
def test_prismatic_first_joint_export_reads_back(tmp_path, capsys, names):
    robot = load_robot_file(TIAGO)
    model = CalibrationModel(robot, ModelSpec.preset("kinematic"))
    rng = np.random.default_rng(5)
    x = model.nominal.copy()
    x += rng.normal(0.0, 2e-3, x.size)  # every row and frame a little off nominal
    b = model.base_index[0]
    x[b] = [0.4, -0.2, 0.1, 0.03, -0.02, 0.5]  # a tracker frame far from the base
    n = model.size
    cal = CalibratedModel(model, x, np.zeros(n), ["estimated"] * n)
    f = save_model(tmp_path / "model.yaml", cal)
    urdf = tmp_path / "cal.urdf"
    extra = ["--names", names] if names else []
    res = run_kinecal(capsys, "export-urdf", f, "--out", urdf, *extra)
    assert res.code == 0, str(res)
    q = ["120", "30", "-20", "-10", "60", "-45", "30", "20"]  # torso 120 mm, arm deg
    a = run_kinecal(capsys, "fk", "--robot", urdf, "--json", "--", *q)
    assert a.code == 0, str(a)
    m = run_kinecal(capsys, "fk", "--model", f, "--json", "--", *q)
    assert m.code == 0, str(m)
    want = json.loads(m.out)["kinematic"]["flange_mm"]
    np.testing.assert_allclose(json.loads(a.out)["flange_mm"], want, atol=1e-6)
