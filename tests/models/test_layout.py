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


STRUCTURED = {
    "full, labelled sets and markers": ModelSpec.preset(
        "full", sets=("", "b"), markers=("m", "n")
    ),
    "rfcm, Hayati, position only": ModelSpec.preset(
        "rfcm", hayati=(2,), cam_rotation=False, markers=("", "tip")
    ),
    "general link bodies": ModelSpec(
        load=True, link="paper", link_bodies=(2, 5), ntm_joints=(2,), ntm_order=3
    ),
}


def _name_from_fields(s):
    """The name a parameter must have, from its structured fields alone."""
    if s.group in ("base", "cam"):
        assert s.joint is None and isinstance(s.label, str)
        return f"{s.group}{'@' + s.label if s.label else ''}.{s.field}"
    assert s.label is None
    if s.group == "link":
        return f"link{s.joint if s.joint is not None else ''}.{s.field}"
    assert s.group in ("joint", "ntm", "load") and s.joint is not None
    return f"joint{s.joint}.{s.field}"


@pytest.mark.parametrize("case", list(STRUCTURED))
def test_issue_19_every_parameter_says_what_it_is_in_fields(case):
    """Group, joint (or body), set/marker label and field of every parameter agree with
    its name, which stays as in model.yaml."""
    m = CalibrationModel(FANUC, STRUCTURED[case])
    for s in m.layout.specs:
        assert _name_from_fields(s) == s.name
        assert s.field and (s.joint is None or s.joint >= 1)


def test_issue_19_labelled_frames_are_found_by_their_group_not_their_name():
    """``cam@n.x`` is a cam-frame parameter: its group says so (its name's first part,
    'cam@n', does not: the reason a warning on frames never fired for labelled ones)."""
    spec = ModelSpec.preset("kinematic", sets=("", "b"), markers=("m", "n"))
    L = CalibrationModel(FANUC, spec).layout
    s = L.specs[L.index("cam@n.x")]
    assert (s.group, s.label, s.field, s.joint) == ("cam", "n", "x", None)
    assert s.name.split(".", 1)[0] == "cam@n"
    frames = L.select(group=("base", "cam"))
    assert [L.names[i] for i in frames] == [
        n for n in L.names if n.startswith(("base", "cam"))
    ]
    assert len(frames) == 4 * 6


def test_issue_19_select_by_group_joint_field_and_label():
    spec = ModelSpec.preset("full", sets=("", "b"), markers=("m", "n"))
    m = CalibrationModel(FANUC, spec)
    L = m.layout
    names = np.array(L.names)
    np.testing.assert_array_equal(
        L.select(group="base", field=("r", "w", "p")), m.base_index[:, 3:].ravel()
    )
    np.testing.assert_array_equal(L.select(group="cam", label="n"), m.cam_index[1])
    np.testing.assert_array_equal(L.select(group="base", label=""), m.base_index[0])
    assert list(names[L.select(joint=2, group="ntm")]) == [
        f"joint2.{c}" for c in ("k0", "ka1", "kb1", "ka2", "kb2")
    ]
    assert list(names[L.select(joint=3)]) == [
        *(f"joint3.{k}" for k in ("theta_offset", "d", "a", "alpha")),
        *(f"joint3.{c}" for c in ("k0", "ka1", "kb1", "ka2", "kb2")),
        "joint3.lambda",
    ]
    assert list(names[L.select(field="lambda")]) == [
        f"joint{j}.lambda" for j in range(1, 7)
    ]
    np.testing.assert_array_equal(L.select(group="load"), L.group_indices("load"))
    assert list(names[L.select(group="link", joint=None)]) == ["link.s1", "link.s2"]
    # label=None: the parameters that are not of a frame; no criterion: all
    assert len(L.select(label=None)) == m.size - 24
    np.testing.assert_array_equal(L.select(), np.arange(m.size))
    assert L.select(group="joint", joint=7).size == 0
    assert L.select(group="joint", joint=7).dtype == np.intp
