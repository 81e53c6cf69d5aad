"""`kinecal export-urdf --like VENDOR.urdf` and `--format ur-calibration` (issue 34).

The vendor files: the LR Mate 200iD URDFs of ROS-Industrial and of FANUC
(tests/data/fanuc_lrmate200id, meshes, limits, FANUC's with inertials) and a UR10e in the
layout of ROS ur_description (tests/data/ur_e_series, meshes, inertials, limits with
effort and velocity). The forward kinematics of the written files are computed by
pinocchio and yourdfpy (optional, skipped when absent) and by the test suite's own
evaluator (tests/urdf_reference.py), never by kinecal.
"""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from kinecal.identification import calibrate
from kinecal.io import read_measurements, save_model
from kinecal.robot import load_robot, robot_from_urdf
from kinecal.simulation import LaserTracker, experiment2
from tests.cli_contract import run_kinecal as _cli
from tests.urdf_reference import urdf_chain_fk

DATA = Path(__file__).resolve().parents[1] / "data"
ROSI = DATA / "fanuc_lrmate200id" / "rosi_lrmate200id.urdf"
FANUC = DATA / "fanuc_lrmate200id" / "fanuc_lrmate200id.urdf"
LR7L = DATA / "fanuc_lrmate200id" / "rosi_lrmate200id7l.urdf"
UR10E = DATA / "ur_e_series" / "ur10e_like_ur_description.urdf"


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    """A kinematic and a full model of the LR Mate twin; a kinematic UR10e model from
    the real motion-capture data."""
    d = tmp_path_factory.mktemp("like")
    e = experiment2(9, n_train=60, tracker=LaserTracker(5e-6, 0.0))
    for name in ("kinematic", "full"):
        save_model(
            d / f"lr_{name}.yaml", calibrate(e.truth.robot, e.train, name).calibrated
        )
    ur = load_robot("ur10e")
    m = read_measurements(DATA / "real" / "ur10_mocap.csv", ur)
    save_model(d / "ur.yaml", calibrate(ur, m, "kinematic").calibrated)
    imported = robot_from_urdf(UR10E, base="world", tip="tool0")
    m = read_measurements(DATA / "real" / "ur10_mocap.csv", imported)
    save_model(d / "ur_imported.yaml", calibrate(imported, m, "kinematic").calibrated)
    return d


def _exported(capsys, *args) -> str:
    """``kinecal export-urdf ARGS``; it must exit 0. Its stdout."""
    code, stdout, err = _cli(capsys, "export-urdf", *map(str, args))
    assert code == 0, err
    return stdout


def _export(capsys, model, vendor, out, *extra):
    return _exported(capsys, model, "--like", vendor, "--out", out, *extra)


def _fk_model(capsys, model, q_deg) -> dict:
    code, out, err = _cli(
        capsys, "fk", "--model", str(model), "--json", "--", *map(str, q_deg)
    )
    assert code == 0, err
    return json.loads(out)["kinematic"]


def _pin_fk(path: Path, frame: str, theta: np.ndarray) -> np.ndarray:
    pin = pytest.importorskip("pinocchio", reason="pinocchio (pip install pin) absent")
    model = pin.buildModelFromXML(path.read_text())
    data = model.createData()
    fid = model.getFrameId(frame, pin.FrameType.BODY)
    out = np.empty((len(theta), 4, 4))
    for k, th in enumerate(theta):
        pin.framesForwardKinematics(model, data, th)
        out[k] = data.oMf[fid].homogeneous
    return out


def _yourdfpy_fk(path: Path, frame: str, names, theta: np.ndarray) -> np.ndarray:
    yourdfpy = pytest.importorskip("yourdfpy", reason="yourdfpy absent (optional)")
    urdf = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True)
    out = np.empty((len(theta), 4, 4))
    for k, th in enumerate(theta):
        urdf.update_cfg(dict(zip(names, th)))
        out[k] = urdf.get_transform(frame, urdf.base_link)
    return out


def _poses(robot, n=6, seed=3):
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    q = np.random.default_rng(seed).uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))
    return q, q @ robot.coupling.T  # controller angles, URDF (kinematic) angles


def _elements(path: Path) -> tuple[dict[str, str], dict[str, ET.Element]]:
    root = ET.parse(path).getroot()
    links = {
        el.get("name", ""): ET.tostring(el, encoding="unicode")
        for el in root.findall("link")
    }
    joints = {el.get("name", ""): el for el in root.findall("joint")}
    return links, joints


@pytest.mark.parametrize(
    ("model", "vendor", "movable"),
    [
        ("lr_kinematic.yaml", ROSI, [f"joint_{i}" for i in range(1, 7)]),
        ("lr_full.yaml", FANUC, [f"J{i}" for i in range(1, 7)]),
        (
            "ur.yaml",
            UR10E,
            ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"]
            + [f"wrist_{i}_joint" for i in (1, 2, 3)],
        ),
    ],
)
def test_issue_34_like_keeps_every_vendor_element_and_moves_only_origins(
    capsys, models, tmp_path, model, vendor, movable
):
    out = tmp_path / "cal.urdf"
    said = _export(capsys, models / model, vendor, out)
    assert "origins moved by up to" in said
    links0, joints0 = _elements(vendor)
    links1, joints1 = _elements(out)
    # Every link (meshes, collisions, inertials) identical; one link more, the tool.
    assert set(links1) == set(links0) | {"calibrated_tool"}
    for name, text in links0.items():
        assert links1[name] == text, name
    assert set(joints1) == set(joints0) | {"calibrated_tool_joint"}
    for name, j0 in joints0.items():
        j1 = joints1[name]
        for tag in ("parent", "child", "axis", "limit", "dynamics", "mimic"):
            a, b = j0.find(tag), j1.find(tag)
            assert (a is None) == (b is None), (name, tag)
            if a is not None and b is not None:
                assert a.attrib == b.attrib, (name, tag)
        assert j1.attrib == j0.attrib
        if name not in movable:
            assert j1.find("origin").attrib == j0.find("origin").attrib, name
    # The origins moved by the calibration only: below 2 mm and 1 deg.
    for name in movable:
        o0, o1 = joints0[name].find("origin"), joints1[name].find("origin")
        xyz0 = np.array(o0.get("xyz").split(), float)
        xyz1 = np.array(o1.get("xyz").split(), float)
        assert np.linalg.norm(xyz1 - xyz0) < 2e-3, name
    m = re.search(r"up to ([0-9.]+) mm, ([0-9.]+) deg", said)
    assert m is not None and 0 < float(m.group(1)) < 2 and 0 < float(m.group(2)) < 1
    # Byte for byte outside the changed origins and the additions.
    text0, text1 = vendor.read_text(), out.read_text()
    strip = re.compile(r"<origin [^>]*/>")
    body1 = re.sub(r"<!--\n  Kinematic part.*?-->\n", "", text1, flags=re.S)
    body1 = body1.replace(
        body1[
            body1.index('  <link name="calibrated_tool"/>') : body1.rindex("</robot>")
        ],
        "",
    )
    assert strip.sub("", body1).replace(" ", "") == strip.sub("", text0).replace(
        " ", ""
    )


@pytest.mark.parametrize(
    ("model", "vendor", "root"),
    [
        ("lr_kinematic.yaml", ROSI, "base_link"),
        ("lr_full.yaml", FANUC, "base_link"),
        ("ur.yaml", UR10E, "world"),
    ],
)
def test_issue_34_like_fk_equals_kinecal_fk_model_in_independent_libraries(
    capsys, models, tmp_path, model, vendor, root
):
    """FK user -> calibrated_tool of the written file, in pinocchio, yourdfpy and the
    suite's own evaluator, equals `kinecal fk --model` (kinematic part) within 1e-4 mm."""
    out = tmp_path / "cal.urdf"
    _export(capsys, models / model, vendor, out, "--user-link", "user")
    from kinecal.io import load_model

    robot = load_model(models / model).model.robot
    q, theta = _poses(robot)
    want = np.array(
        [_fk_model(capsys, models / model, np.degrees(qk))["tool_mm"] for qk in q]
    )
    _, joints = _elements(out)
    names = [
        n for n, j in joints.items() if j.get("type") in ("revolute", "continuous")
    ]
    got = {
        "reference": np.array(
            [urdf_chain_fk(out, "user", "calibrated_tool", th)[:3, 3] for th in theta]
        )
    }
    try:
        got["pinocchio"] = _pin_fk(out, "calibrated_tool", theta)[:, :3, 3]
    except pytest.skip.Exception:
        pass
    try:
        got["yourdfpy"] = _yourdfpy_fk(out, "calibrated_tool", names, theta)[:, :3, 3]
    except pytest.skip.Exception:
        pass
    assert {"pinocchio", "yourdfpy"} & set(got) or not _importable(
        "pinocchio", "yourdfpy"
    )
    for lib, p in got.items():
        assert np.abs(p * 1e3 - want).max() < 1e-4, lib
    # The vendor's own links stay the vendor's: its flange (ROS-I, FANUC) or tool0 (UR)
    # sits where the model puts the physical flange.
    plain = tmp_path / "plain.urdf"
    _export(capsys, models / model, vendor, plain)
    flange = "tool0" if vendor == UR10E else "flange"
    ref = np.array([urdf_chain_fk(plain, root, flange, th)[:3, 3] for th in theta])
    fl = np.array(
        [_fk_model(capsys, models / model, np.degrees(qk))["flange_mm"] for qk in q]
    )
    if vendor == UR10E:  # the DH base frame is base_link_inertia: Rz(pi) from world
        fl = fl * [-1.0, -1.0, 1.0]
    shift = ref * 1e3 - fl  # the robot base in the vendor root: a constant
    assert np.ptp(shift, axis=0).max() < 1e-6
    if vendor != UR10E:  # FANUC World = base_link 330 mm up
        assert np.abs(shift - [0.0, 0.0, 330.0]).max() < 1e-6


def test_issue_34_like_on_the_vendor_root_is_the_user_frame_moved(
    capsys, models, tmp_path
):
    """Without --user-link the root stays the vendor's; FK root -> tool is the model's
    tool pose seen from the calibrated robot base (the same for every pose)."""
    a, b = tmp_path / "a.urdf", tmp_path / "b.urdf"
    _export(capsys, models / "lr_kinematic.yaml", ROSI, a)
    _export(capsys, models / "lr_kinematic.yaml", ROSI, b, "--user-link", "user")
    _, theta = _poses(load_robot("fanuc-lrmate200id"))
    T_root_user = np.linalg.inv(urdf_chain_fk(b, "user", "base_link", theta[0]))
    for th in theta:
        Ta = urdf_chain_fk(a, "base_link", "calibrated_tool", th)
        Tb = urdf_chain_fk(b, "user", "calibrated_tool", th)
        assert np.abs(Ta - T_root_user @ Tb).max() < 1e-12


def test_issue_34_ur_calibration_yaml_drops_into_ur_description(
    capsys, models, tmp_path
):
    """The six origins of kinematics.yaml, put into the ur_description chain, give the
    calibrated forward kinematics (the --like export's, which equals the model)."""
    from kinecal import _yaml as yaml

    kin = tmp_path / "kinematics.yaml"
    _exported(capsys, models / "ur.yaml", "--format", "ur-calibration", "--out", kin)
    doc = yaml.load(kin.read_text())["kinematics"]
    assert re.fullmatch(r"calib_\d+", doc["hash"])
    parts = ("shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3")
    assert set(doc) == {*parts, "hash"}
    text = UR10E.read_text()
    for part, jn in zip(
        parts,
        (
            "shoulder_pan_joint",
            "shoulder_lift_joint",
            "elbow_joint",
            "wrist_1_joint",
            "wrist_2_joint",
            "wrist_3_joint",
        ),
    ):
        v = doc[part]
        xyz = " ".join(repr(v[k]) for k in ("x", "y", "z"))
        rpy = " ".join(repr(v[k]) for k in ("roll", "pitch", "yaw"))
        new = f'<origin xyz="{xyz}" rpy="{rpy}"/>'
        text = re.sub(
            rf'(<joint name="{jn}".*?)<origin [^>]*/>',
            lambda m, new=new: m.group(1) + new,
            text,
            count=1,
            flags=re.S,
        )
    sub = tmp_path / "ur_with_yaml.urdf"
    sub.write_text(text)
    like = tmp_path / "like.urdf"
    _export(capsys, models / "ur.yaml", UR10E, like)
    _, theta = _poses(load_robot("ur10e"))
    for th in theta:
        A = urdf_chain_fk(sub, "world", "tool0", th)
        B = urdf_chain_fk(like, "world", "tool0", th)
        # 1e-10: the fixture's 1.570796327 for pi/2 against the exact DH template
        assert np.abs(A - B).max() < 1e-9
    code, _, err = _cli(
        capsys,
        "export-urdf",
        str(models / "lr_kinematic.yaml"),
        "--format",
        "ur-calibration",
        "--out",
        str(tmp_path / "x.yaml"),
    )
    assert code != 0 and "not a Universal Robots arm" in err


def _refused(capsys, model, vendor, out, *extra) -> str:
    """``export-urdf MODEL --like VENDOR --out OUT EXTRA`` failed without a traceback;
    its stderr."""
    code, _, err = _cli(
        capsys, "export-urdf", str(model), "--like", str(vendor), "--out", str(out),
        *extra,
    )  # fmt: skip
    assert code != 0 and "Traceback" not in err, err
    return err


def test_issue_34_like_refuses_a_vendor_file_that_does_not_fit(
    capsys, models, tmp_path
):
    out = tmp_path / "cal.urdf"
    lr = models / "lr_kinematic.yaml"
    err = _refused(capsys, lr, LR7L, out)
    assert "from the nominal axes of fanuc-lrmate200id" in err
    assert "ur10e" in _refused(capsys, models / "ur.yaml", ROSI, out)
    bad = tmp_path / "bad.urdf"
    rosi = ROSI.read_text()
    for text, words in (
        ("<robot name='x'><link name='a'/>", "cannot read URDF"),
        ("<xacro:macro name='x'/>", "cannot read URDF"),
        (
            '<robot xmlns:xacro="http://www.ros.org/wiki/xacro">'
            '<xacro:property name="a" value="1"/></robot>',
            "xacro",
        ),
        (
            "<robot name='x'><link name='a'/><link name='b'/><joint name='j' "
            "type='revolute'><parent link='a'/><child link='b'/></joint></robot>",
            "has 1 movable joints",
        ),
        (
            rosi.replace('xyz="0 0 0.330"', 'xyz="0 0 nan"', 1),
            "expected 3 finite numbers",
        ),
        # the forearm offset 10 mm longer: another robot
        (rosi.replace('xyz="0 0 0.035"', 'xyz="0 0 0.045"'), "from the nominal axes"),
        (
            rosi.replace(
                '<axis xyz="0 0 1"/>', '<axis xyz="0 0 1"/><mimic joint="joint_2"/>', 1
            ),
            "is a mimic joint",
        ),
    ):
        bad.write_text(text)
        assert words in _refused(capsys, lr, bad, out), (text, words)
    err = _refused(capsys, lr, ROSI, out, "--tool-link", "tool0")
    assert "already has a link 'tool0'" in err
    for extra, words in (
        (("--tool-link", ""), "expected a link name"),
        (("--tool-link", "a b"), "expected a link name"),
        (("--tool-link", "t", "--user-link", "t"), "both 't'"),
    ):
        assert words in _refused(capsys, lr, ROSI, out, *extra)
    assert not out.exists()


def _importable(*names: str) -> bool:
    import importlib.util

    return any(importlib.util.find_spec(n) is not None for n in names)


def test_issue_34_like_of_an_imported_robot_puts_the_tip_on_the_model_flange(
    capsys, models, tmp_path
):
    """The robot imported from the vendor's URDF (import-urdf, world -> tool0): FK from
    the vendor's root to its tip link equals `kinecal fk --model`'s kinematic
    flange_mm and wpr (DESIGN: third wave), the tool hangs below the tip."""
    out = tmp_path / "cal.urdf"
    said = _export(capsys, models / "ur_imported.yaml", UR10E, out)
    assert "tip 'tool0'" in said
    _, joints = _elements(out)
    assert joints["calibrated_tool_joint"].find("parent").get("link") == "tool0"
    from kinecal.geometry import matrix_to_wpr

    q, theta = _poses(robot_from_urdf(UR10E, base="world", tip="tool0"))
    for qk, th in zip(q, theta):
        want = _fk_model(capsys, models / "ur_imported.yaml", np.degrees(qk))
        T = urdf_chain_fk(out, "world", "tool0", th)
        assert np.abs(T[:3, 3] * 1e3 - want["flange_mm"]).max() < 1e-4
        wpr = np.degrees(matrix_to_wpr(T[:3, :3]))
        assert np.abs((wpr - want["wpr_deg"] + 180) % 360 - 180).max() < 1e-6


def test_issue_34_plain_export_has_one_link_set_per_robot(models):
    """Two calibrations of one robot, J2's zero 8 deg apart (the LR Mate's J2 origin sits
    at the roll-pitch-yaw lock nominally; 8 deg off it, the values alone would not split
    it): the same links, and each file reproduces its own chain."""
    from dataclasses import replace

    from kinecal.compensation import export_chain
    from kinecal.io import load_model, urdf_text
    from kinecal.io._urdf_export import stable_splits

    cal = load_model(models / "lr_kinematic.yaml")
    lay = cal.model.layout
    x = cal.params.copy()
    x[lay.index("joint2.theta_offset")] += np.radians(8.0)
    other = replace(cal, params=x)
    q, theta = _poses(cal.model.robot, 4)
    link_sets = []
    for c in (cal, other):
        chain = export_chain(c)
        text = urdf_text(chain, name="r", comments=[], split=stable_splits(c))
        root = ET.fromstring(text)
        link_sets.append(sorted(el.get("name") for el in root.findall("link")))
        f = Path(models / "plain_check.urdf")
        f.write_text(text)
        for qk, th in zip(q, theta):
            want = chain.fk(qk[None], "tool")[0]
            np.testing.assert_allclose(
                urdf_chain_fk(f, "user", "tool", th), want, atol=1e-12
            )
    assert link_sets[0] == link_sets[1]
    assert "j2_pre" in link_sets[0]


def test_issue_34_plain_export_carries_velocities_never_zero(capsys, models, tmp_path):
    """Velocities come from the robot file (the LR Mate's from the ROS-I URDF; J3 in
    kinematic angles moves at J2's + J3's); import-urdf reads velocity and effort and the
    robot YAML keeps them; no <limit> says 0."""
    from kinecal import _yaml as yaml
    from kinecal.robot import dump_robot, robot_from_dict

    for extra in ((), ("--coupling", "mimic")):
        out = tmp_path / "plain.urdf"
        _exported(capsys, models / "lr_kinematic.yaml", "--out", out, "--force", *extra)
        lims = {
            j.get("name"): j.find("limit").attrib
            for j in ET.parse(out).getroot().findall("joint")
            if j.find("limit") is not None
        }
        assert all(
            float(a["velocity"]) > 0 and float(a["effort"]) > 0 for a in lims.values()
        )
        v = {k: np.degrees(float(a["velocity"])) for k, a in lims.items()}
        assert v["j1"] == pytest.approx(450) and v["j6"] == pytest.approx(1000)
        assert v["j3"] == pytest.approx(380 + 520 if not extra else 520)
    r = robot_from_urdf(UR10E)
    assert r.joints[0].velocity == pytest.approx(2.0944) and r.joints[3].effort == 56
    again = robot_from_dict(yaml.load(yaml.dump(dump_robot(r))), source="<t>")
    assert [j.velocity for j in again.joints] == pytest.approx(
        [j.velocity for j in r.joints]
    )
    assert [j.effort for j in again.joints] == [j.effort for j in r.joints]
    bad = dump_robot(r)
    bad["joints"][0]["velocity"] = 0
    with pytest.raises(Exception, match=r"joints\[0\]\.velocity|velocity.*positive"):
        robot_from_dict(bad, source="<t>")


def test_issue_34_names_robot_uses_the_robots_joint_names(capsys, models, tmp_path):
    """--names robot: an imported robot's joint names (ur_description's), links
    base_link .. tool0, root base_link; the frames those of the kinecal-named file."""
    plain, named = tmp_path / "plain.urdf", tmp_path / "named.urdf"
    model = models / "ur_imported.yaml"
    for out, extra in ((plain, ()), (named, ("--names", "robot"))):
        _exported(capsys, model, "--out", out, *extra)
    links, joints = _elements(named)
    want = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint"]
    want += [f"wrist_{i}_joint" for i in (1, 2, 3)]
    movable = [n for n, j in joints.items() if j.get("type") != "fixed"]
    assert movable == want
    assert {"base_link", "user", "flange", "tool0"} <= set(links)
    assert {f"link_{i}" for i in range(1, 7)} <= set(links)
    _, theta = _poses(robot_from_urdf(UR10E, base="world", tip="tool0"), 4)
    for th in theta:
        A = urdf_chain_fk(named, "base_link", "tool0", th)
        B = urdf_chain_fk(plain, "base", "tool", th)
        np.testing.assert_allclose(A, B, atol=1e-12)
        U = urdf_chain_fk(named, "base_link", "user", th)
        np.testing.assert_allclose(
            U @ urdf_chain_fk(plain, "user", "tool", th), A, atol=1e-12
        )
    try:
        T = _pin_fk(named, "tool0", theta)
        for th, Tk in zip(theta, T):
            np.testing.assert_allclose(
                Tk, urdf_chain_fk(named, "base_link", "tool0", th), atol=1e-12
            )
    except pytest.skip.Exception:
        pass
    # read back as --robot: base_link and flange recognised, the joint names kept
    r = robot_from_urdf(named)
    assert [j.name for j in r.joints] == want and "base_link -> flange" in r.source
    code, _, err = _cli(
        capsys,
        "export-urdf",
        str(model),
        "--out",
        str(tmp_path / "x"),
        "--names",
        "robot",
        "--format",
        "yaml-dh",
    )
    assert code != 0 and "--names" in err


def test_issue_35_export_and_import_never_overwrite_their_input(
    capsys, models, tmp_path
):
    vendor = tmp_path / "vendor.urdf"
    vendor.write_bytes(ROSI.read_bytes())
    model = tmp_path / "model.yaml"
    model.write_bytes((models / "lr_kinematic.yaml").read_bytes())
    for args in (
        ("export-urdf", str(model), "--like", str(vendor), "--out", str(vendor)),
        ("export-urdf", str(model), "--out", str(model)),
        ("import-urdf", str(vendor), "--out", str(vendor)),
    ):
        code, _, err = _cli(capsys, *args, "--force")
        assert code != 0 and "is an input of this command" in err, err
    assert vendor.read_bytes() == ROSI.read_bytes()
    assert model.read_bytes() == (models / "lr_kinematic.yaml").read_bytes()


def test_issue_34_like_a_vendor_file_with_other_numbers_warns_and_stays_exact(
    capsys, models, tmp_path
):
    """The forearm offset 0.3 mm off (a data sheet's rounding): written, with a warning
    naming the difference; the FK still equals `kinecal fk --model`."""
    vendor = tmp_path / "rounded.urdf"
    vendor.write_text(ROSI.read_text().replace('xyz="0 0 0.035"', 'xyz="0 0 0.0353"'))
    out = tmp_path / "cal.urdf"
    code, _, err = _cli(
        capsys,
        "export-urdf",
        str(models / "lr_kinematic.yaml"),
        "--like",
        str(vendor),
        "--out",
        str(out),
        "--user-link",
        "user",
    )
    assert code == 0, err
    m = re.search(r"warning: .* ([0-9.]+) mm \(or mrad\) away", err)
    assert m is not None and 0.2 < float(m.group(1)) < 1.0, err
    q, theta = _poses(load_robot("fanuc-lrmate200id"), 3)
    for qk, th in zip(q, theta):
        want = _fk_model(capsys, models / "lr_kinematic.yaml", np.degrees(qk))[
            "tool_mm"
        ]
        got = urdf_chain_fk(out, "user", "calibrated_tool", th)[:3, 3] * 1e3
        assert np.abs(got - want).max() < 1e-4


@pytest.mark.parametrize("key", ["lrmate", "lrmate-hayati"])
def test_issue_34_like_with_hayati_rows_sets_and_markers(key, tmp_path):
    """Every parameter off nominal (Hayati beta on J2 included), two sets, two markers:
    one tool link per marker; FK user -> tool of each, for either set, equals the model's
    kinematic part (the joint axes stay the vendor's)."""
    from kinecal.compensation import kinematic_params
    from kinecal.io._urdf_like import like_urdf
    from kinecal.models import ModelInputs
    from tests.compensation.test_issue_23_export import _case

    cal = _case(key, np.random.default_rng(7))
    q, theta = _poses(cal.model.robot, 5)
    x = kinematic_params(cal)
    for s, set_label in enumerate(cal.model.spec.sets):
        res = like_urdf(cal, ROSI, set_label=set_label, user_link="user")
        assert res.check_m < 1e-9
        assert set(res.tips.values()) == {"calibrated_tool_m1", "calibrated_tool_m2"}
        root = ET.fromstring(res.text)
        axes0 = {
            j.get("name"): j.find("axis")
            for j in ET.parse(ROSI).getroot().iter("joint")
        }
        for j in root.iter("joint"):
            if j.get("name") in axes0 and axes0[j.get("name")] is not None:
                assert j.find("axis").attrib == axes0[j.get("name")].attrib
        f = tmp_path / f"like_{s}.urdf"
        f.write_text(res.text)
        for m, marker in enumerate(cal.model.spec.markers):
            inp = ModelInputs.make(
                q, set_index=np.full(len(q), s), marker_index=np.full(len(q), m)
            )
            out = cal.model.evaluate(x, inp, orientation=True)
            for k, th in enumerate(theta):
                T = urdf_chain_fk(f, "user", res.tips[marker], th)
                np.testing.assert_allclose(T[:3, 3], out.p_user[k], atol=1e-10)
                np.testing.assert_allclose(T[:3, :3], out.R_user_cam[k], atol=1e-10)


def test_issue_33_model_yaml_accepts_joint_name_aliases(models, tmp_path):
    """A parameter key may be the robot's joint name (shoulder_lift_joint.d) for the
    canonical joint2.d; both at once is an error naming them."""
    import yaml as _yaml

    from kinecal.errors import ConfigError
    from kinecal.io import load_model
    from kinecal.robot._param_names import display_parameter_name

    src = models / "ur_imported.yaml"
    canon = load_model(src)
    doc = _yaml.safe_load(src.read_text())
    names = canon.model.robot.joint_names
    doc["parameters"] = {
        display_parameter_name(k, names): v for k, v in doc["parameters"].items()
    }
    assert "shoulder_lift_joint.theta_offset" in doc["parameters"] or any(
        k.startswith("shoulder_lift_joint.") for k in doc["parameters"]
    )
    aliased = tmp_path / "aliased.yaml"
    aliased.write_text(_yaml.safe_dump(doc))
    np.testing.assert_array_equal(load_model(aliased).params, canon.params)
    k = next(k for k in doc["parameters"] if k.startswith("shoulder_lift_joint."))
    doc["parameters"]["joint2." + k.partition(".")[2]] = doc["parameters"][k]
    aliased.write_text(_yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match="name one parameter"):
        load_model(aliased)


def test_issue_33_refit_names_accept_joint_name_aliases(models):
    """refit(names=...) takes shoulder_lift_joint.a for joint2.a: the same result."""
    from kinecal.identification import refit
    from kinecal.io import load_model

    cal = load_model(models / "ur_imported.yaml")
    imported = robot_from_urdf(UR10E, base="world", tip="tool0")
    m = read_measurements(DATA / "real" / "ur10_mocap.csv", imported)
    m = m.subset(np.arange(min(60, m.n)))
    a = refit(cal, m, names=["joint2.a"])
    b = refit(cal, m, names=["shoulder_lift_joint.a"])
    np.testing.assert_array_equal(a.params, b.params)
    with pytest.raises(ValueError, match="unknown parameter"):
        refit(cal, m, names=["no_such_joint.a"])
