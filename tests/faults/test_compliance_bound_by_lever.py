"""The bound of a joint compliance in a model file is a deflection, not a number of rad/m.

A fit of real data of the robot ended beyond the old bound of 0.1 rad/m and the whole
calibration was refused as "measurements of another robot": a KUKA KR210 twin with a
100 kg payload and harmonics the model lacks gave J6 -1.57 rad/m. J6 carries 0.2 mm of
lever per unit payload weight there (the tool on its axis): 0.02 deg of deflection. The
bound is now 0.1 rad of deflection at the joint's largest gravity torque (at least 0.1
rad/m, as before for the joints that carry much)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from kinecal.errors import ConfigError
from kinecal.io._model_bounds import check_value, compliance_bound
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import load_robot
from tests.cli_contract import run_kinecal

KR210 = Path(__file__).resolve().parents[1] / "data" / "vendor_urdf" / "kuka_kr210.urdf"


def _kr210():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # its first axis off the base link's z
        return load_robot(str(KR210))


def test_the_bound_is_a_deflection_at_the_largest_torque():
    lr = load_robot("fanuc-lrmate200id")
    assert compliance_bound(lr, 2) == 0.13  # J2: 0.74 m of lever, as before ~0.1
    assert compliance_bound(lr, 1) >= 1e4  # no gravity torque about J1
    kr = _kr210()
    model = CalibrationModel(kr, ModelSpec(load=True))
    i6 = model.layout.index("joint6.lambda")
    i2 = model.layout.index("joint2.lambda")
    check_value(model, i6, -1.57, "joint6.lambda")  # a wrist with the tool on its axis
    with pytest.raises(
        ConfigError, match=r"joint2.lambda: -1.57 rad/m.*0.1 rad of def"
    ):
        check_value(model, i2, -1.57, "joint2.lambda")


def test_a_heavy_payload_twin_with_unmodelled_harmonics_calibrates(tmp_path, capsys):
    d = tmp_path / "twin"
    res = run_kinecal(
        capsys, "simulate", "--robot", KR210, "--out", d, "--n-train", "150",
        "--n-test", "20", "--payload-kg", "100", "--extras", "harmonics", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    res = run_kinecal(
        capsys, "calibrate", d / "train.csv", "--robot", d / "robot.yaml",
        "--model", "full", "--cv", "off", "--out", tmp_path / "cal", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    assert (tmp_path / "cal" / "model.yaml").exists()
