"""Issue 23, items 1 and 2: the calibrated kinematic part as a URDF and as a DH table.

The URDF is read back by two parsers that share no code with kinecal (one written here on
xml.etree and scipy, and pinocchio), on several robots (the coupled LR Mate, a UR10 with
Hayati rows, the 7-joint Franka FR3 given in Craig's convention, a robot with a prismatic
joint), with several markers and several sets: its forward kinematics equal the model's
kinematic part to 1e-9 m at every pose.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal import _yaml as yaml
from kinecal.compensation import (
    check_chain,
    dh_description,
    export_chain,
    geometry_loss,
    kinematic_params,
)
from kinecal.errors import ConfigError, DataError
from kinecal.identification import CalibratedModel
from kinecal.io._urdf_export import robot_yaml_text, urdf_text
from kinecal.models import CalibrationModel, ModelInputs, ModelSpec
from kinecal.robot import load_robot, robot_from_dict

TOL = 1e-9  # [m], [rad]: the issue's bound per point

PRISMATIC_ROBOT = {
    "name": "slide-arm",
    "convention": "dh",
    "units": {"length": "mm", "angle": "deg"},
    "joints": [
        {"theta_offset": 10, "d": 300, "a": 40, "alpha": -90, "limits": [-170, 170]},
        {"theta_offset": -90, "d": 0, "a": 0, "alpha": -90, "type": "prismatic",
         "limits": [100, 600]},
        {"theta_offset": 0, "d": 0, "a": 250, "alpha": 0, "limits": [-150, 150]},
        {"theta_offset": 30, "d": 120, "a": 0, "alpha": 90, "limits": [-180, 180]},
        {"theta_offset": 0, "d": 90, "a": 0, "alpha": 0, "limits": [-360, 360]},
    ],
    "tool": {"x": 5, "y": -3, "z": 80, "r": 10, "w": 20, "p": -30},
    "self_weight": None,
}  # fmt: skip


def _perturbed(robot, spec, rng) -> CalibratedModel:
    """A 'calibrated' model: every parameter moved off nominal by a tolerance-sized
    amount, user frames anywhere, compliance terms non-zero."""
    m = CalibrationModel(robot, spec)
    x = m.nominal.copy()
    for i, ps in enumerate(m.layout.specs):
        k = ps.kind
        if ps.group == "base":
            x[i] += rng.uniform(-1.5, 1.5) if k == "length" else rng.uniform(-3, 3)
        elif k == "length":
            x[i] += rng.normal() * 2e-3
        elif k == "angle":
            x[i] += rng.normal() * 5e-3
        elif k == "ntm":
            x[i] = rng.normal() * 2e-4
        elif k == "compliance":
            x[i] = rng.normal() * 1e-3
        elif k == "moment":
            x[i] = rng.normal() * 0.5
        else:
            x[i] = rng.normal()
    P = m.size
    return CalibratedModel(m, x, np.full(P, np.nan), ["estimated"] * P, 2.0)


CASES = {
    "lrmate": ("fanuc-lrmate200id", dict(name="full", hayati=())),
    "lrmate-hayati": ("fanuc-lrmate200id", dict(name="full", hayati=(2,))),
    "ur10-hayati": ("ur10", dict(name="full", hayati=(2, 3))),
    "fr3-7dof-mdh": ("franka-fr3", dict(name="ntm", has_self_weight=False)),
    "prismatic": (PRISMATIC_ROBOT, dict(name="ntm", has_self_weight=False)),
}


def _case(key, rng, sets=("A", "B"), markers=("m1", "m2")):
    robot_ref, opts = CASES[key]
    opts = dict(opts)
    robot = (
        load_robot(robot_ref)
        if isinstance(robot_ref, str)
        else robot_from_dict(robot_ref, source="test")
    )
    spec = ModelSpec.preset(opts.pop("name"), sets=sets, markers=markers, **opts)
    if robot.name == "slide-arm":
        spec = spec.with_(ntm_joints=(1, 3))
    return _perturbed(robot, spec, rng)


def _poses(robot, rng, n=60):
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    return rng.uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))


# ------------------------------------------------------------------ independent URDF FK
def _urdf_fk(
    text: str, root: str, tip: str, values: dict[str, np.ndarray]
) -> np.ndarray:
    """Pose (N, 4, 4) of ``tip`` in ``root`` from the URDF text, joint values by name
    (mimic joints follow their joint). xml.etree and scipy only."""
    tree = ET.fromstring(text)
    by_child = {j.find("child").get("link"): j for j in tree.iter("joint")}
    chain = []
    link = tip
    while link != root:
        j = by_child[link]
        chain.append(j)
        link = j.find("parent").get("link")
    N = len(next(iter(values.values())))
    T = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
    for j in reversed(chain):
        o = j.find("origin")
        O = np.eye(4)
        O[:3, :3] = Rotation.from_euler(
            "xyz", [float(v) for v in o.get("rpy").split()]
        ).as_matrix()
        O[:3, 3] = [float(v) for v in o.get("xyz").split()]
        T = T @ O
        kind = j.get("type")
        if kind == "fixed":
            continue
        axis = np.array([float(v) for v in j.find("axis").get("xyz").split()])
        mim = j.find("mimic")
        if mim is not None:
            v = float(mim.get("multiplier")) * values[mim.get("joint")] + float(
                mim.get("offset")
            )
        else:
            v = values[j.get("name")]
        M = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
        if kind == "prismatic":
            M[:, :3, 3] = v[:, None] * axis
        else:
            M[:, :3, :3] = Rotation.from_rotvec(v[:, None] * axis).as_matrix()
        T = T @ M
    return T


def _model_tool(cal, q, s, m):
    N = q.shape[0]
    inp = ModelInputs.make(q, set_index=np.full(N, s), marker_index=np.full(N, m))
    return cal.model.evaluate(kinematic_params(cal), inp, orientation=True)


def _urdf_values(cal, q, coupling):
    theta = q @ cal.model.robot.coupling.T if coupling == "kinematic" else q
    return {f"j{i + 1}": theta[:, i] for i in range(q.shape[1])}


@pytest.mark.parametrize("key", sorted(CASES))
@pytest.mark.parametrize("coupling", ["kinematic", "mimic"])
def test_issue_23_urdf_fk_equals_the_kinematic_model(key, coupling, rng):
    cal = _case(key, rng)
    q = _poses(cal.model.robot, rng)
    for s, set_label in enumerate(cal.model.spec.sets):
        chain = export_chain(cal, set_label=set_label, coupling=coupling)
        text = urdf_text(chain, name="x", comments=["test -- with dashes"])
        ET.fromstring(text)  # well-formed, the comment too
        for m, marker in enumerate(cal.model.spec.markers):
            ref = _model_tool(cal, q, s, m)
            T = _urdf_fk(text, "user", f"tool_{marker}", _urdf_values(cal, q, coupling))
            assert np.abs(T[:, :3, 3] - ref.p_user).max() < TOL
            assert np.abs(T[:, :3, :3] - ref.R_user_cam).max() < TOL
        # The other set's user frame hangs under the base: user(A) -> user(B).
        other = 1 - s
        T_ab = _urdf_fk(
            text,
            "user",
            f"user_{cal.model.spec.sets[other]}",
            _urdf_values(cal, q[:1], coupling),
        )
        Rb, tb = cal.model.base_frames(kinematic_params(cal))
        T_base = np.eye(4), np.eye(4)
        for k in (s, other):
            T_base[k][:3, :3], T_base[k][:3, 3] = Rb[k], tb[k]
        np.testing.assert_allclose(
            T_ab[0], T_base[s] @ np.linalg.inv(T_base[other]), atol=TOL
        )


@pytest.mark.parametrize("key", ["lrmate", "ur10-hayati", "fr3-7dof-mdh", "prismatic"])
def test_urdf_fk_by_pinocchio(key, rng):
    pin = pytest.importorskip(
        "pinocchio", reason="pinocchio (pip install pin) not installed"
    )
    cal = _case(key, rng, sets=("",), markers=("",))
    coupling = "mimic"  # controller angles; pinocchio applies the mimic joints
    text = urdf_text(export_chain(cal, coupling=coupling), name="x", comments=["t"])
    model = pin.buildModelFromXML(text, mimic=True)
    data = model.createData()
    tool = model.getFrameId("tool", pin.FrameType.BODY)
    q = _poses(cal.model.robot, rng, 30)
    ref = _model_tool(cal, q, 0, 0)
    for k in range(q.shape[0]):
        qp = np.zeros(model.nq)
        for i in range(q.shape[1]):
            qp[model.joints[model.getJointId(f"j{i + 1}")].idx_q] = q[k, i]
        pin.framesForwardKinematics(model, data, qp)
        M = data.oMf[tool]
        assert np.abs(M.translation - ref.p_user[k]).max() < TOL
        assert np.abs(M.rotation - ref.R_user_cam[k]).max() < TOL


def test_urdf_origins_near_gimbal_lock_are_split(rng):
    """The LR Mate's J2 origin (alpha1 = -90, offset2 = -90) is exactly at pitch 90 deg
    in roll-pitch-yaw: it is written as two origins, each far from the lock."""
    cal = _case("lrmate", rng, sets=("",), markers=("",))
    x = cal.params.copy()
    lay = cal.model.layout
    x[lay.index("joint1.alpha")] = -np.pi / 2
    x[lay.index("joint2.theta_offset")] = -np.pi / 2
    cal = CalibratedModel(cal.model, x, cal.std, cal.status, 2.0)
    text = urdf_text(export_chain(cal), name="x", comments=["t"])
    assert '<joint name="j2_pre" type="fixed">' in text
    for o in ET.fromstring(text).iter("origin"):
        pitch = float(o.get("rpy").split()[1])
        assert abs(pitch) < np.radians(85)
    q = _poses(cal.model.robot, rng)
    T = _urdf_fk(text, "user", "tool", _urdf_values(cal, q, "kinematic"))
    assert np.abs(T[:, :3, 3] - _model_tool(cal, q, 0, 0).p_user).max() < TOL


@pytest.mark.parametrize("key", sorted(CASES))
def test_yaml_dh_is_loadable_and_reproduces_the_kinematic_model(key, rng):
    cal = _case(key, rng)
    robot = cal.model.robot
    for m, marker in enumerate(cal.model.spec.markers):
        desc, T_user_base = dh_description(cal, set_label="B", marker=marker)
        text = robot_yaml_text(desc, comments=["test"])
        again = robot_from_dict(yaml.load(text), source="exported.yaml")
        assert again.convention == robot.convention
        np.testing.assert_array_equal(again.coupling, robot.coupling)
        q = _poses(robot, rng)
        ref = _model_tool(cal, q, 1, m)
        T = T_user_base @ again.fk_tool(q)
        assert np.abs(T[:, :3, 3] - ref.p_user).max() < TOL
        assert np.abs(T[:, :3, :3] - ref.R_user_cam).max() < TOL
        # As a nominal robot it is a model again: calibrating from it starts exact.
        m2 = CalibrationModel(again, ModelSpec.preset("kinematic"))
        p_nom = m2.evaluate(m2.nominal, ModelInputs.make(q)).p_user
        T_b = np.linalg.inv(T_user_base)
        assert np.abs(ref.p_user @ T_b[:3, :3].T + T_b[:3, 3] - p_nom).max() < TOL


def test_chain_checks_errors_and_loss(rng):
    cal = _case("lrmate", rng)
    chain = export_chain(cal, set_label="B")
    assert check_chain(cal, chain, "B", _poses(cal.model.robot, rng)) < 1e-12
    with pytest.raises(DataError, match="set 'C' is not in the model"):
        export_chain(cal, set_label="C")
    with pytest.raises(DataError, match="marker 'x' is not in the model"):
        dh_description(cal, marker="x")
    with pytest.raises(ConfigError, match="coupling must be one of"):
        export_chain(cal, coupling="sum")
    # A coupling the mimic joints cannot express (a diagonal other than +-1).
    bad = load_robot("fanuc-lrmate200id")
    C = bad.coupling.copy()
    C[2, 2] = 2.0
    from dataclasses import replace

    cal2 = _perturbed(replace(bad, coupling=C), ModelSpec.preset("kinematic"), rng)
    with pytest.raises(ConfigError, match="needs a coupling matrix with"):
        export_chain(cal2, coupling="mimic")
    assert check_chain(cal2, export_chain(cal2), None, _poses(bad, rng)) < 1e-12
    # The accuracy the compliance terms carry: zero for the kinematic part itself.
    inp = ModelInputs.make(_poses(cal.model.robot, rng))
    loss = geometry_loss(cal, inp)
    assert loss.n == 60 and 0 < loss.rms <= loss.max
    geo = CalibratedModel(cal.model, kinematic_params(cal), cal.std, cal.status, 2.0)
    assert geometry_loss(geo, inp).max == 0.0
