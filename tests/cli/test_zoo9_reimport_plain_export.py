"""`export-urdf` (root 'user') of a gantry (three slides and a turning quill, numbers
made up), read back by `import-urdf`: the robot base must be the export's 'base' link,
the frame `kinecal fk --model` reports in. The importer took the deepest fixed link on
the first axis instead, the export's own turned 'j1_pre' frame, so the re-imported
robot's flange was 2 m away from the model's."""

from __future__ import annotations

import json
import warnings

import numpy as np

from kinecal.io import save_model
from kinecal.robot import robot_from_urdf
from tests.cli_contract import run_kinecal
from tests.helpers import perturbed_kinematic

_J = (
    '<joint name="{0}" type="{1}"><parent link="{2}"/><child link="{3}"/>'
    '<origin xyz="{4}" rpy="0 0 0"/><axis xyz="{5}"/>'
    '<limit lower="{6}" upper="{7}" effort="1" velocity="1"/></joint>'
)
_GANTRY = (
    '<?xml version="1.0"?><robot name="gantry">'
    + "".join(f'<link name="{n}"/>' for n in ("base", "cx", "cy", "cz", "tool"))
    + _J.format("x", "prismatic", "base", "cx", "0.1 0.2 1.5", "1 0 0", 0, 2)
    + _J.format("y", "prismatic", "cx", "cy", "0 0 0", "0 1 0", 0, 1.5)
    + _J.format("z", "prismatic", "cy", "cz", "0 0 0", "0 0 -1", 0, 0.8)
    + _J.format("rz", "revolute", "cz", "tool", "0 0 -0.2", "0 0 1", -3, 3)
    + "</robot>"
)


def test_zoo9_plain_export_reimports_with_the_model_base(tmp_path, capsys):
    src = tmp_path / "gantry.urdf"
    src.write_text(_GANTRY)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # frame0 turned onto the first axis: reported
        robot = robot_from_urdf(src)
    cal = perturbed_kinematic(robot, 4)
    f = save_model(tmp_path / "model.yaml", cal)
    out = tmp_path / "cal.urdf"
    res = run_kinecal(capsys, "export-urdf", f, "--out", out)
    assert res.code == 0, str(res)
    assert '<link name="j1_pre"/>' in out.read_text()  # the case: a turned pre-frame
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # frame0 turned onto the first axis: reported
        again = robot_from_urdf(out)
    assert "URDF base -> flange" in again.source
    lim = robot.limits
    for q in np.random.default_rng(2).uniform(lim[:, 0], lim[:, 1], (3, 4)):
        ctrl = np.where(robot.prismatic, q * 1e3, np.degrees(q))
        m = run_kinecal(capsys, "fk", "--model", f, "--json", "--", *map(str, ctrl))
        assert m.code == 0, str(m)
        want = np.array(json.loads(m.out)["kinematic"]["flange_mm"])
        got = again.fk_flange(q)[:3, 3] * 1e3
        assert np.abs(got - want).max() < 1e-4
