"""Issue 34, small items: "a robot file without payload but data with a payload column:
the saved model's robot shows the data's payload". Not a bug: with link masses, the
self-weight terms are per unit of the reference payload (kinecal.robot._gravity: every
body's weight relative to ``robot.payload_kg``), so the saved robot must carry the
payload the model was identified with; the calibration is the same as with a robot
file that states it, and the model reloads to the same predictions."""

from __future__ import annotations

import numpy as np
import yaml

from kinecal.io import load_model, read_measurements
from tests.independent_arm import UR6, urdf_text


def test_payload_from_the_data_is_the_models_reference(tmp_path, run_cli_here):
    urdf = tmp_path / "ur6.urdf"
    urdf.write_text(urdf_text(UR6, "ur6"))
    twin = tmp_path / "twin"
    res = run_cli_here(
        "simulate", "--robot", str(urdf), "--out", str(twin), "--n-train", "60",
        "--n-test", "20", "--payload-kg", "2", "-q",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    doc = yaml.safe_load((twin / "robot.yaml").read_text())
    assert doc.pop("payload_kg") == 2
    bare = tmp_path / "bare.yaml"
    bare.write_text(yaml.safe_dump(doc))
    models = {}
    for name, robot in (("stated", twin / "robot.yaml"), ("bare", bare)):
        out = tmp_path / name
        res = run_cli_here(
            "calibrate", str(twin / "train.csv"), "--robot", str(robot), "--model",
            "full", "--out", str(out), "-q",
        )  # fmt: skip
        assert res.returncode in (0, 3), res.stderr
        models[name] = load_model(out / "model.yaml")
    for cal in models.values():
        assert cal.model.robot.payload_kg == 2 == cal.reference_payload_kg
    a, b = models["stated"], models["bare"]
    np.testing.assert_allclose(a.params, b.params, rtol=0, atol=1e-9)
    test = read_measurements(twin / "test.csv", a.model.robot)
    pa = a.model.evaluate(a.params, test.model_inputs(2.0)).p_user
    pb = b.model.evaluate(b.params, test.model_inputs(2.0)).p_user
    np.testing.assert_allclose(pa, pb, atol=1e-9)
