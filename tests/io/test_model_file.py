"""model.yaml: complete, loadable again, safe to write."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

from kinecal.errors import ConfigError
from kinecal.identification import calibrate
from kinecal.io import load_model, save_model


@pytest.fixture(scope="module")
def result():
    from kinecal.simulation import LaserTracker, experiment2

    e = experiment2(21, tracker=LaserTracker(5e-6, 0.0), n_side=6)
    return e, calibrate(e.truth.robot, e.train, "full")


def test_save_load_reproduces_predictions(result, tmp_path):
    e, res = result
    f = save_model(tmp_path / "model.yaml", res.calibrated)
    back = load_model(f)
    np.testing.assert_allclose(back.params, res.params, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(
        back.std[res.identifiability.free],
        res.std[res.identifiability.free],
        rtol=1e-12,
    )
    assert back.status == res.calibrated.status
    a = res.calibrated.predict(e.test).raw_position
    b = back.predict(e.test).raw_position
    np.testing.assert_allclose(a, b, atol=1e-12)


def test_every_parameter_has_unit_value_std_status(result, tmp_path):
    _, res = result
    f = save_model(tmp_path / "model.yaml", res.calibrated)
    doc = yaml.safe_load(f.read_text())
    params = doc["parameters"]
    assert len(params) == res.model.size == 50
    assert params["joint3.a"]["unit"] == "mm"
    assert params["joint2.alpha"]["unit"] == "deg"
    assert params["joint2.lambda"]["unit"] == "rad/m"
    assert params["link.s1"]["unit"] == "mm"
    for entry in params.values():
        assert set(entry) == {"value", "std", "unit", "status"}
    assert (
        params["joint3.d"]["status"] == "unidentifiable"
        and params["joint3.d"]["std"] is None
    )
    assert doc["frames_mm_deg"]["base"]["x"] == pytest.approx(
        res.model.frame_euler(res.params, "base")[0, 0] * 1e3
    )


def test_no_overwrite_without_force(result, tmp_path):
    _, res = result
    f = save_model(tmp_path / "model.yaml", res.calibrated)
    with pytest.raises(FileExistsError, match="use --force"):
        save_model(f, res.calibrated)
    save_model(f, res.calibrated, force=True)
    assert not list(tmp_path.glob(".*.tmp"))  # atomic: no temporary left behind


def test_bad_model_files(result, tmp_path):
    _, res = result
    f = save_model(tmp_path / "model.yaml", res.calibrated)
    doc = yaml.safe_load(f.read_text())
    doc["parameters"]["joint3.a"]["unit"] = "m"
    g = tmp_path / "bad.yaml"
    g.write_text(yaml.safe_dump(doc))
    with pytest.raises(
        ConfigError, match=r"parameters.joint3.a.unit: expected 'mm'; got 'm'"
    ):
        load_model(g)
    del doc["parameters"]["joint3.a"]
    g.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=r"missing 'joint3\.a'"):
        load_model(g)
    g.write_text("name: not-a-model\n")
    with pytest.raises(ConfigError, match="not a kinecal model file"):
        load_model(g)
    with pytest.raises(ConfigError, match="model file not found"):
        load_model(tmp_path / "nope.yaml")
