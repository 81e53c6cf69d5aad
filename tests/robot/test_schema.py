"""Robot YAML validation: every bad file gives a one-line error naming the key."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from kinecal.errors import ConfigError
from kinecal.geometry import make_transform, rot_x, rot_z
from kinecal.robot import (
    builtin_robot_names,
    dump_robot,
    load_robot,
    load_robot_file,
    robot_from_dict,
)

GOOD = {
    "name": "test-bot",
    "convention": "dh",
    "units": {"length": "mm", "angle": "deg"},
    "joints": [
        {"theta_offset": 0, "d": 300, "a": 50, "alpha": -90, "limits": [-170, 170]},
        {"theta_offset": -90, "d": 0, "a": 400, "alpha": 0},
        {"theta_offset": 0, "d": 0, "a": 30, "alpha": -90},
        {"theta_offset": 0, "d": 400, "a": 0, "alpha": 90},
        {"theta_offset": 0, "d": 0, "a": 0, "alpha": -90},
        {"theta_offset": 0, "d": 80, "a": 0, "alpha": 0},
    ],
}


def _bad(mutate):
    d = copy.deepcopy(GOOD)
    mutate(d)
    return d


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d["joints"][2].pop("alpha"), r"joints\[2\]: missing key 'alpha'"),
        (lambda d: d["joints"][1].update(alfa=3), r"joints\[1\]: unknown key 'alfa'"),
        (lambda d: d.update(colour="red"), r"unknown key 'colour'"),
        (
            lambda d: d["units"].update(angle="dgree"),
            r"units.angle: expected one of deg, rad; got 'dgree'",
        ),
        (lambda d: d["units"].update(length="inch"), r"units.length"),
        (lambda d: d.pop("joints"), r"missing key 'joints'"),
        (lambda d: d.update(convention="dhm"), r"convention: expected 'dh' or 'mdh'"),
        (
            lambda d: d["joints"][0].update(d="a lot"),
            r"joints\[0\].d: expected a number",
        ),
        (
            lambda d: d["joints"][0].update(limits=[10, -10]),
            r"joints\[0\].limits: lower limit",
        ),
        (
            lambda d: d.update(coupling=[{"joint": 3, "from": 9, "factor": 1}]),
            r"coupling\[0\].from",
        ),
        (
            lambda d: d["units"].update(angle="rad"),
            r"joints\[0\].alpha: -90.0 is not an angle in rad",
        ),
        (
            lambda d: d["units"].update(length="m"),
            r"joints\[0\].d: 300.0 m is not a plausible",
        ),
        (
            lambda d: d.update(gravity=[0, 0, 0]),
            r"gravity: must not be the zero vector",
        ),
        (lambda d: d.update(tool={"x": 1, "roll": 2}), r"tool: unknown key 'roll'"),
        (lambda d: d["joints"][0].update(type="spherical"), r"joints\[0\].type"),
    ],
)
def test_bad_robot_documents(mutate, match):
    with pytest.raises(ConfigError, match=match) as info:
        robot_from_dict(_bad(mutate), source="bot.yaml")
    msg = str(info.value)
    assert msg.startswith("bot.yaml: ")
    assert "\n" not in msg


def test_bad_files(tmp_path):
    with pytest.raises(ConfigError, match="robot file not found"):
        load_robot(tmp_path / "missing.yaml")
    p = tmp_path / "empty.yaml"
    p.write_text("")
    with pytest.raises(ConfigError, match="empty"):
        load_robot_file(p)
    p.write_text("name: [unclosed")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_robot_file(p)
    with pytest.raises(ConfigError, match="unknown robot 'nobody'"):
        load_robot("nobody")


def test_good_document_in_si():
    r = robot_from_dict(GOOD)
    assert r.n_joints == 6
    assert r.joints[0].d == pytest.approx(0.3)
    assert r.joints[0].alpha == pytest.approx(-np.pi / 2)
    assert r.limits[0, 1] == pytest.approx(np.radians(170))
    assert np.isinf(r.limits[1]).all()


def test_coupling_matrix():
    r = load_robot("fanuc-lrmate200id")
    q = np.radians([10.0, 20.0, 30.0, 0.0, 0.0, 0.0])
    th = r.theta_from_ctrl(q)
    assert np.degrees(th[2]) == pytest.approx(50.0)
    np.testing.assert_allclose(r.ctrl_from_theta(th), q, atol=1e-15)


@pytest.mark.parametrize("name", builtin_robot_names())
def test_dump_load_round_trip(name, rng):
    r = load_robot(name)
    r2 = robot_from_dict(yaml.safe_load(yaml.safe_dump(dump_robot(r))))
    q = rng.uniform(-1, 1, size=(20, r.n_joints))
    np.testing.assert_allclose(r2.fk_tool(q), r.fk_tool(q), atol=1e-13)
    np.testing.assert_allclose(r2.coupling, r.coupling)
    np.testing.assert_allclose(r2.limits, r.limits, atol=1e-12)


@settings(max_examples=30, deadline=None)
@given(
    rows=st.lists(
        st.tuples(
            *(st.floats(-180, 180) for _ in range(2)),
            *(st.floats(-500, 500) for _ in range(2)),
        ),
        min_size=2,
        max_size=7,
    )
)
def test_mdh_regrouping_equals_direct_craig_product(rows):
    doc = {
        "name": "mdh-bot",
        "convention": "mdh",
        "units": {"length": "mm", "angle": "deg"},
        "joints": [
            {"theta_offset": o, "alpha": al, "a": a, "d": d} for o, al, a, d in rows
        ],
        "flange": {"z": 100},
    }
    r = robot_from_dict(doc)
    q = np.linspace(-1, 1, r.n_joints)
    T = np.eye(4)
    for (o, al, a, d), qi in zip(rows, q):
        # Craig: Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)
        T = (
            T
            @ make_transform(rot_x(np.radians(al)), [0, 0, 0])
            @ make_transform(np.eye(3), [a * 1e-3, 0, 0])
        )
        T = T @ make_transform(rot_z(np.radians(o) + qi), [0, 0, d * 1e-3])
    T = T @ make_transform(np.eye(3), [0, 0, 0.1])
    np.testing.assert_allclose(r.fk_flange(q), T, atol=1e-12)


def test_prismatic_joint_adds_to_d():
    doc = copy.deepcopy(GOOD)
    doc["joints"][0]["type"] = "prismatic"
    r = robot_from_dict(doc)
    q = np.zeros(6)
    T0 = r.fk_flange(q)
    q[0] = 0.1
    T1 = r.fk_flange(q)
    np.testing.assert_allclose(T1[:3, 3] - T0[:3, 3], [0, 0, 0.1], atol=1e-15)


def test_priors_in_the_robot_file_are_read_in_file_units_and_round_trip():
    doc = {
        **GOOD,
        "units": {"length": "m", "angle": "rad"},
        "joints": [
            {**j, "d": j["d"] / 1e3, "a": j["a"] / 1e3, "alpha": np.radians(j["alpha"])}
            for j in GOOD["joints"]
        ],
        "priors": {"joint_length": 0.005, "joint_angle": 0.01, "ntm": None},
    }
    for j in doc["joints"]:
        j.pop("limits", None)
        j["theta_offset"] = np.radians(j["theta_offset"])
    r = robot_from_dict(doc)
    assert r.prior_sigma[("joint", "length")] == pytest.approx(0.005)
    assert r.prior_sigma[("joint", "angle")] == pytest.approx(0.01)
    assert np.isinf(r.prior_sigma[("ntm", "ntm")])
    d = dump_robot(r)  # mm, deg
    assert d["priors"]["joint_length"] == pytest.approx(5.0)
    assert d["priors"]["joint_angle"] == pytest.approx(np.degrees(0.01))
    assert d["priors"]["ntm"] is None
    r2 = robot_from_dict(yaml.safe_load(yaml.safe_dump(d)))
    assert r2.prior_sigma == pytest.approx(r.prior_sigma)


@pytest.mark.parametrize(
    ("priors", "match"),
    [
        ({"joint_lenght": 1}, "joint_lenght"),
        ({"joint_length": -1}, r"priors.joint_length: expected a positive std"),
        ({"joint_angle": "wide"}, r"priors.joint_angle"),
    ],
)
def test_bad_priors(priors, match):
    with pytest.raises(ConfigError, match=match):
        robot_from_dict({**GOOD, "priors": priors})
