"""Parameter layouts: exact names, sizes of the paper's models, pack/unpack round trips."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinecal.errors import ModelError
from kinecal.models import CalibrationModel, ModelSpec, ParameterLayout, ParamSpec
from kinecal.robot import load_robot

FANUC = load_robot("fanuc-lrmate200id")


@pytest.mark.parametrize(
    ("preset", "cam_rotation", "size"),
    [
        ("kinematic", True, 30),
        ("kinematic", False, 27),
        ("ntm", True, 45),
        ("rfcm", True, 39),
        ("full", True, 53),
        ("full", False, 50),
    ],
)
def test_paper_model_sizes(preset, cam_rotation, size):
    m = CalibrationModel(FANUC, ModelSpec.preset(preset, cam_rotation=cam_rotation))
    assert m.size == size


def test_exact_names_of_the_full_model():
    m = CalibrationModel(FANUC, ModelSpec.preset("full"))
    names = m.layout.names
    assert names[:6] == ["base.x", "base.y", "base.z", "base.r", "base.w", "base.p"]
    assert names[6:8] == ["joint1.a", "joint1.alpha"]
    assert names[8:12] == [
        "joint2.theta_offset",
        "joint2.d",
        "joint2.a",
        "joint2.alpha",
    ]
    assert (
        "joint6.theta_offset" not in m.layout
    )  # the last joint keeps only its rotation
    assert "joint1.d" not in m.layout  # absorbed by the base frame
    assert names[24:30] == ["cam.x", "cam.y", "cam.z", "cam.r", "cam.w", "cam.p"]
    assert names[30:35] == [
        "joint1.k0",
        "joint1.ka1",
        "joint1.kb1",
        "joint1.ka2",
        "joint1.kb2",
    ]
    assert names[45:51] == [f"joint{j}.lambda" for j in range(1, 7)]
    assert names[51:] == ["link.s1", "link.s2"]


def test_hayati_row_replaces_d_with_beta():
    m = CalibrationModel(FANUC, ModelSpec.preset("kinematic", hayati=(2,)))
    assert "joint2.beta" in m.layout and "joint2.d" not in m.layout
    assert m.size == 30
    with pytest.raises(ModelError, match=r"Hayati rows are for joints 2\.\.5"):
        CalibrationModel(FANUC, ModelSpec.preset("kinematic", hayati=(6,)))
    with pytest.raises(ModelError, match="needs axis 3 parallel to axis 4"):
        CalibrationModel(FANUC, ModelSpec.preset("kinematic", hayati=(3,)))


def test_sets_and_markers_get_their_own_frames():
    spec = ModelSpec.preset(
        "kinematic", cam_rotation=False, sets=("a", "b"), markers=("m1", "m2", "m3")
    )
    m = CalibrationModel(FANUC, spec)
    assert m.size == 12 + 2 + 16 + 9
    assert (
        "base@b.p" in m.layout and "cam@m3.z" in m.layout and "cam@m1.r" not in m.layout
    )


def test_seven_axis_robot_sizes():
    franka = load_robot("franka-fr3")
    assert (
        CalibrationModel(franka, ModelSpec.preset("kinematic")).size
        == 6 + 2 + 4 * 5 + 6
    )
    with pytest.raises(ModelError, match="no self_weight"):
        CalibrationModel(franka, ModelSpec.preset("full"))
    assert (
        CalibrationModel(franka, ModelSpec.preset("full", has_self_weight=False)).size
        == 34 + 15 + 7
    )


def test_unknown_names_and_presets():
    m = CalibrationModel(FANUC, ModelSpec.preset("kinematic"))
    with pytest.raises(ModelError, match=r"unknown parameter 'joint7\.theta_offset'"):
        m.layout.index("joint7.theta_offset")
    with pytest.raises(ModelError, match="unknown model 'fancy'"):
        ModelSpec.preset("fancy")
    with pytest.raises(ModelError, match="duplicate"):
        ParameterLayout([ParamSpec("a", "length", "g"), ParamSpec("a", "angle", "g")])


@settings(max_examples=50, deadline=None)
@given(values=st.lists(st.floats(-1e3, 1e3, allow_nan=False), min_size=53, max_size=53))
def test_pack_unpack_round_trip(values):
    layout = CalibrationModel(FANUC, ModelSpec.preset("full")).layout
    v = np.array(values)
    np.testing.assert_array_equal(layout.pack(layout.unpack(v)), v)


def test_transfer_between_layouts(rng):
    full = CalibrationModel(FANUC, ModelSpec.preset("full"))
    kin = CalibrationModel(FANUC, ModelSpec.preset("kinematic"))
    v = rng.normal(size=full.size)
    w = kin.layout.transfer(v, full.layout)
    assert w[kin.layout.index("joint3.a")] == v[full.layout.index("joint3.a")]
    back = full.layout.transfer(w, kin.layout)
    assert back[full.layout.index("link.s1")] == 0.0
