"""Issue 34 on real vendor URDFs (tests/data/vendor_urdf, sources in its README): each is
imported (`import-urdf`, the chain found alone and named), a calibrated model of it is
written as `export-urdf --like` the vendor's file, and the copy's forward kinematics are
checked against `kinecal fk --model` by the suite's own evaluator, yourdfpy and
pinocchio (optional), never by kinecal. The files hold what real URDFs hold:
CAD-exported origins, rounded pi/2 (1.5708), a first axis along -z or a few mm off the
base link's z axis, balancer linkages of mimic joints, grippers with mimic fingers,
transmissions and gazebo tags."""

from __future__ import annotations

import importlib.util
import json
import re
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import ConfigError
from kinecal.io import save_model
from kinecal.robot import robot_from_urdf
from tests.cli_contract import run_kinecal
from tests.helpers import perturbed_kinematic
from tests.urdf_reference import urdf_chain_fk

VENDOR = Path(__file__).resolve().parents[1] / "data" / "vendor_urdf"
# file -> (base, tip, joints) found without --base/--tip
CHAINS = {
    "kuka_kr210.urdf": ("base_link", "tool0", 6),
    "kinova_gen3_7dof.urdf": ("base_link", "end_effector_link", 7),
    "kinova_gen3_lite.urdf": ("BASE", "DUMMY", 6),
    "abb_irb6640.urdf": ("base_link", "tool0", 6),
    "xarm6_gripper.urdf": ("world", "xarm_gripper_base_link", 6),
    "motoman_sia10d.urdf": ("world", "link_t", 7),
}


def _import(path: Path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # base moved, fingers left: tested below
        return robot_from_urdf(path, **kw)


def _poses(robot, n=4, seed=2):
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    return np.random.default_rng(seed).uniform(
        lim[:, 0], lim[:, 1], (n, robot.n_joints)
    )


@pytest.mark.parametrize("name", sorted(CHAINS))
def test_issue_34_vendor_urdf_imports_with_its_forward_kinematics(name):
    """The chain found alone is the arm (no balancer, no finger), the same as named;
    its flange is the file's tip link in the file's base link (the robot keeps the shift
    of its DH frame 0 onto the first axis as ``frame0``; rounded pi/2 read as exact:
    micrometres)."""
    base, tip, n = CHAINS[name]
    path = VENDOR / name
    robot = _import(path)
    assert robot.n_joints == n
    assert f"URDF {base} -> {tip}" in robot.source
    named = _import(path, base=base, tip=tip)
    q = _poses(robot)
    np.testing.assert_allclose(named.fk_flange(q), robot.fk_flange(q), atol=1e-12)
    F = [urdf_chain_fk(path, base, tip, qk) for qk in q]
    B = [Fk @ np.linalg.inv(Rk) for Fk, Rk in zip(F, robot.fk_flange(q))]
    for Bk in B:
        assert np.abs(Bk - np.eye(4)).max() < 5e-5  # [m, rad]
    assert np.allclose(B[0][:3, :3] @ -robot.gravity, [0, 0, 9.80665], atol=1e-3)


@pytest.mark.parametrize("name", sorted(CHAINS))
def test_issue_34_vendor_urdf_like_export_equals_the_model(name, tmp_path, capsys):
    out = _like(VENDOR / name, tmp_path, capsys)
    # The copy reads back as a robot (--robot CAL.urdf): the same joints, base and tip
    # (below the user link, the base link moved onto a calibrated first axis).
    base, tip, n = CHAINS[name]
    again = _import(out)
    assert [j.name for j in again.joints] == [
        j.name for j in _import(VENDOR / name).joints
    ]
    assert again.n_joints == n and f" -> {tip}" in again.source
    if base != "world":
        assert f"URDF {base} -> " in again.source


def _like(path: Path, tmp_path: Path, capsys, **chain) -> Path:
    """export-urdf --like ``path`` of a perturbed model of it (its chain: ``chain``,
    base and tip), checked; the copy."""
    robot = _import(path, **chain)
    cal = perturbed_kinematic(robot, 5)
    f = save_model(tmp_path / "model.yaml", cal)
    out = tmp_path / "cal.urdf"
    res = run_kinecal(
        capsys, "export-urdf", f, "--like", path, "--out", out, "--user-link", "user"
    )
    assert res.code == 0, str(res)
    # A model of this very file: no "N mm away from the model's nominal robot" warning
    # (the vendor's rounded pi/2 read alike by the import and by --like).
    assert "nominal robot" not in res.err, res.err
    # The vendor's text byte for byte but for the movable joints' origins and the
    # appended user and tool links.
    text0, text1 = path.read_text(), out.read_text()
    body1 = text1[: text1.rindex('  <link name="calibrated_tool"/>')]
    body1 = re.sub(r"<!--\n  Kinematic part.*?-->\n", "", body1, count=1, flags=re.S)
    strip = re.compile(r"<origin\b[^>]*/>")
    assert strip.sub("", body1) == strip.sub("", text0[: text0.rindex("</robot>")])
    j0 = {j.get("name"): j for j in ET.parse(path).getroot().findall("joint")}
    j1 = {j.get("name"): j for j in ET.parse(out).getroot().findall("joint")}
    names = [j.name for j in robot.joints]
    for jn, j in j0.items():
        if j.get("type") and jn not in names:
            o0, o1 = j.find("origin"), j1[jn].find("origin")
            assert (o0 is None and o1 is None) or o0.attrib == o1.attrib, jn
    q = _poses(robot, n=3)
    theta = q @ robot.coupling.T
    written = out
    if 'xmlns="' in text1:  # the evaluators read plain tags: read it without
        out = tmp_path / "cal_plain.urdf"
        out.write_text(re.sub(r' xmlns="[^"]*"', "", text1, count=1))
    for qk, th in zip(q, theta):
        m = run_kinecal(
            capsys, "fk", "--model", f, "--json", "--", *map(str, _ctrl(robot, qk))
        )
        assert m.code == 0, str(m)
        want = np.array(json.loads(m.out)["kinematic"]["tool_mm"])
        got = urdf_chain_fk(out, "user", "calibrated_tool", th)[:3, 3] * 1e3
        assert np.abs(got - want).max() < 1e-4
    for lib, fk in (("yourdfpy", _yourdfpy_fk), ("pinocchio", _pinocchio_fk)):
        if importlib.util.find_spec(lib) is None:
            continue  # optional libraries (the dev venv has both)
        got_all = fk(out, names, theta)
        for th, got in zip(theta, got_all):
            want = urdf_chain_fk(out, "user", "calibrated_tool", th)
            assert np.abs(got - want).max() < 1e-9, lib
    return written


def _yourdfpy_fk(path: Path, names: list[str], theta: np.ndarray) -> list[np.ndarray]:
    import yourdfpy

    u = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True)
    out = []
    for th in theta:
        u.update_cfg(dict(zip(names, th)))
        out.append(u.get_transform("calibrated_tool", "user"))
    return out


def _pinocchio_fk(path: Path, names: list[str], theta: np.ndarray) -> list[np.ndarray]:
    """pinocchio (root link ``user`` is its universe): the chain's joints set, the
    others (fingers, linkages) at their neutral values; a continuous joint is (cos,
    sin)."""
    import pinocchio as pin

    model = pin.buildModelFromXML(path.read_text())
    data = model.createData()
    fid = model.getFrameId("calibrated_tool")
    out = []
    for th in theta:
        q = pin.neutral(model)
        for name, t in zip(names, th):
            jm = model.joints[model.getJointId(name)]
            if jm.nq == 2:
                q[jm.idx_q : jm.idx_q + 2] = [np.cos(t), np.sin(t)]
            else:
                q[jm.idx_q] = t
        pin.framesForwardKinematics(model, data, q)
        out.append(data.oMf[fid].homogeneous)
    return out


def _ctrl(robot, q: np.ndarray) -> np.ndarray:
    """Controller values as `kinecal fk` takes them: deg, mm for a slide."""
    return np.where(robot.prismatic, q * 1e3, np.degrees(q))


def _track(t: str) -> str:
    """The arm on a horizontal track (a slide along -y under its base)."""
    return t.replace(
        '<joint name="world-base" type="fixed">',
        '<joint name="world-base" type="prismatic"><axis xyz="0 -1 0"/>'
        '<limit lower="-1" upper="2" effort="1000" velocity="1"/>',
    )


def _crlf(t: str) -> str:
    return t.replace("\n", "\r\n")


def _no_origin(t: str) -> str:
    return re.sub(
        r'(<joint name="joint_r" type="revolute">\s*)<origin[^>]*/>', r"\1", t
    )


def _cdata(t: str) -> str:
    plugin = '<joint name="joint_s" type="revolute"><origin xyz="0 0 0"/></joint>'
    return t.replace("</robot>", f"<gazebo><![CDATA[{plugin}]]></gazebo>\n</robot>")


def _xmlns(t: str) -> str:
    return t.replace("<robot ", '<robot xmlns="http://www.ros.org" ', 1)


@pytest.mark.parametrize(
    ("change", "encoding"),
    [
        (_crlf, "utf-8"),
        (str, "utf-8-sig"),
        (_no_origin, "utf-8"),
        (_cdata, "utf-8"),
        (_xmlns, "utf-8"),
        (_track, "utf-8"),
    ],
    ids=["crlf", "bom", "no-origin", "cdata", "xmlns", "track"],
)
def test_issue_34_like_keeps_the_vendor_text_as_written(
    change, encoding, tmp_path, capsys
):
    """CRLF line ends, a byte order mark, a movable joint without <origin>, a gazebo
    plugin's CDATA naming a joint, a default XML namespace, a horizontal track under
    the arm: read, and the copy keeps them (the byte order mark, the line ends)."""
    path = tmp_path / "vendor.urdf"
    text = change((VENDOR / "motoman_sia10d.urdf").read_text())
    path.write_bytes(text.encode(encoding))
    out = _like(path, tmp_path, capsys)
    data = out.read_bytes()
    assert data.startswith(b"\xef\xbb\xbf") == (encoding == "utf-8-sig")
    if change is _crlf:
        assert data.count(b"\n") == data.count(b"\r\n")
    if change is _cdata:
        cdata = text[text.index("<gazebo><![CDATA[") : text.index("</gazebo>")]
        assert cdata in out.read_text()


def test_issue_34_vendor_urdf_warnings_and_refusals(tmp_path, capsys):
    with pytest.warns(UserWarning, match=r"base \(DH frame 0\) is base_link moved by "):
        robot_from_urdf(VENDOR / "kinova_gen3_7dof.urdf")
    with pytest.warns(UserWarning, match="not in the robot: joint_cylinder"):
        robot_from_urdf(VENDOR / "abb_irb6640.urdf")
    with pytest.warns(UserWarning, match="6 of the file's 12 movable joints"):
        robot_from_urdf(VENDOR / "xarm6_gripper.urdf")
    res = run_kinecal(
        capsys, "import-urdf", VENDOR / "abb_irb5400.urdf", "--out", tmp_path / "r.yaml"
    )
    assert res.code == 2
    assert "abb_irb5400.urdf" in res.err and "'joint5b'" in res.err
    assert "Traceback" not in res.err


def test_issue_34_like_picks_the_arm_of_a_two_arm_file_by_its_joint_names(
    tmp_path, capsys
):
    """Two DENSO arms on a frame: found alone the chain branches (refused, naming both
    arms); the second arm imported by name is exported --like the whole file, its
    joints found by name (the first arm's origins untouched)."""
    dual = VENDOR / "denso_dual.urdf"
    with pytest.raises(ConfigError, match=r"branches at link 'frame' \(base_link_1"):
        robot_from_urdf(dual)
    out = _like(dual, tmp_path, capsys, base="base_link_2", tip="handtip2")
    j0 = {j.get("name"): j for j in ET.parse(dual).getroot().findall("joint")}
    j1 = {j.get("name"): j for j in ET.parse(out).getroot().findall("joint")}

    def origin(j: ET.Element) -> dict | None:
        el = j.find("origin")
        return None if el is None else el.attrib

    moved = {n for n in j0 if origin(j0[n]) != origin(j1[n])}
    assert moved == {f"joint_{k}" for k in range(7, 13)}


def test_issue_34_xacro_is_refused_with_what_to_do(tmp_path, capsys):
    """An unexpanded xacro (import-urdf, --robot) names its first xacro element and how
    to expand it (it was "no joints; expected a serial chain", and --robot FILE.xacro
    "not valid YAML")."""
    macro = tmp_path / "arm_macro.xacro"
    macro.write_text(
        '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
        '<xacro:macro name="arm" params="prefix"><link name="${prefix}base"/>'
        "</xacro:macro></robot>"
    )
    for argv in (
        ("import-urdf", macro, "--out", tmp_path / "r.yaml"),
        ("simulate", "--robot", macro, "--out", tmp_path / "sim"),
    ):
        res = run_kinecal(capsys, *argv)
        assert res.code == 2 and "Traceback" not in res.err
        assert "arm_macro.xacro: holds xacro elements (<xacro:macro 'arm'>)" in res.err
        assert "xacro FILE.xacro > FILE.urdf" in res.err
