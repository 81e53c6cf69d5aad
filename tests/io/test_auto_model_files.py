"""Every model file ``--model auto`` can write loads again (issue 31, point 1).

The chosen candidate's label becomes the model name ``auto:<label>``; the labels depend on
the robot (self-weight layout or not, NTM joints), so every label ``candidate_specs`` can
produce, on every built-in robot, for point, pose and sensor data with several sets and
markers, is saved and read back; one order-1 file goes through the commands that take a
model.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from kinecal.errors import ConfigError
from kinecal.identification import CalibratedModel, candidate_specs
from kinecal.io import load_model, save_model
from kinecal.measurement._measurements import Measurements
from kinecal.models import CalibrationModel
from kinecal.robot import builtin_robot_names, load_robot
from tests.conftest import kinecal_cli as run_cli


def _meas(n_joints: int, kind: str, sets: int, markers: int) -> Measurements:
    n = 4
    extra: dict[str, object] = {}
    if kind == "pose":
        extra["R_user_cam"] = np.broadcast_to(np.eye(3), (n, 3, 3)).copy()
    if kind == "sensor":
        extra["target_index"] = np.zeros(n, np.intp)
        extra["targets"] = np.zeros((1, 3))
        extra["target_labels"] = ("s1",)
    return Measurements(
        kind=kind,
        q_ctrl=np.zeros((n, n_joints)),
        p=np.zeros((n, 3)),
        set_index=np.arange(n) % sets,
        set_labels=tuple(f"S{i}" for i in range(sets)) if sets > 1 else ("",),
        marker_index=np.arange(n) % markers,
        marker_labels=tuple(f"M{i}" for i in range(markers)) if markers > 1 else ("",),
        rows=np.arange(1, n + 1),
        **extra,  # type: ignore[arg-type]
    )


def _cases():
    for name in builtin_robot_names():
        for kind, sets, markers in (("point", 1, 1), ("pose", 2, 1), ("sensor", 1, 2)):
            yield name, kind, sets, markers


@pytest.mark.parametrize(("robot_name", "kind", "sets", "markers"), list(_cases()))
def test_every_candidate_label_saves_and_loads(
    robot_name, kind, sets, markers, tmp_path
):
    robot = load_robot(robot_name)
    meas = _meas(robot.n_joints, kind, sets, markers)
    labels = []
    for label, spec in candidate_specs(robot, meas):
        labels.append(label)
        model = CalibrationModel(robot, replace(spec, name=f"auto:{label}"))
        rng = np.random.default_rng(len(labels))
        params = model.nominal + 1e-6 * rng.standard_normal(model.size)
        cal = CalibratedModel(
            model, params, np.full(model.size, 1e-6), ["estimated"] * model.size, 1.0
        )
        f = save_model(tmp_path / f"{len(labels)}.yaml", cal)
        back = load_model(f)
        assert back.model.spec == cal.model.spec, label
        np.testing.assert_allclose(back.params, cal.params, rtol=1e-12, atol=1e-15)
    assert sum("order 1" in lab for lab in labels) >= 2, labels


@pytest.mark.parametrize(
    "name", ["auto:", "auto: full", "auto:full\norder", "auto:" + "x" * 81, 3, None]
)
def test_malformed_auto_names_are_refused(name, tmp_path):
    robot = load_robot("fanuc-lrmate200id")
    model = CalibrationModel(
        robot, candidate_specs(robot, _meas(6, "point", 1, 1))[0][1]
    )
    cal = CalibratedModel(
        model, model.nominal, np.zeros(model.size), ["estimated"] * model.size
    )
    f = save_model(tmp_path / "m.yaml", cal)
    text = f.read_text().replace("name: kinematic", f"name: {json.dumps(name)}")
    f.write_text(text)
    with pytest.raises(ConfigError, match="unknown model"):
        load_model(f)


@pytest.fixture(scope="module")
def order1_model(tmp_path_factory):
    """A real calibration whose model is the 'full order 1' candidate, as auto writes it."""
    from kinecal.identification import calibrate
    from kinecal.io import write_measurements
    from kinecal.simulation import LaserTracker, experiment2

    d = tmp_path_factory.mktemp("auto1")
    e = experiment2(5, tracker=LaserTracker(5e-6, 0.0), n_side=5)
    robot = e.truth.robot
    label, spec = next(
        (lab, s) for lab, s in candidate_specs(robot, e.train) if lab == "full order 1"
    )
    res = calibrate(robot, e.train, replace(spec, name=f"auto:{label}"))
    f = save_model(d / "model.yaml", res.calibrated)
    data = write_measurements(d / "test.csv", e.test, robot)
    return f, data, robot


def test_order1_model_file_is_read_by_every_command(order1_model, tmp_path):
    f, data, robot = order1_model
    r = run_cli("evaluate", str(data), "--model", str(f), "--json")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["rms_mm"] < 0.05
    r = run_cli("fk", "--model", str(f), *["0"] * robot.n_joints, "--json")
    assert r.returncode == 0, r.stderr
    r = run_cli("export-urdf", str(f), "--out", str(tmp_path / "c.urdf"))
    assert r.returncode == 0, r.stderr
    r = run_cli(
        "compensate", str(data), "--model", str(f), "--out", str(tmp_path / "c.csv")
    )
    assert r.returncode in (0, 4), r.stderr
    assert (tmp_path / "c.csv").exists()
