"""A URDF robot whose first joint axis is not its base link's z axis keeps the base link
as its robot base: the shift of DH frame 0 onto the first axis is the description's
``T_base_0`` (robot YAML ``frame0``), so that the nominal pose (``fk --robot``) is the
URDF's base link -> tip pose (what tf gives), checked with the suite's own evaluator
(tests/urdf_reference.py) and yourdfpy. Calibration fits the user frame -> joint 1 frame
whatever the robot base: it gives the same accuracy as with the base moved onto the
axis (the previous import)."""

from __future__ import annotations

import importlib.util
import json
import re
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal import _yaml as yaml
from kinecal.compensation import robot_base_offset
from kinecal.identification import calibrate, evaluate
from kinecal.io import load_model, save_model
from kinecal.measurement import CalibratedModel
from kinecal.models import CalibrationModel, ModelSpec
from kinecal.robot import dump_robot, load_robot, robot_from_dict, robot_from_urdf
from kinecal.simulation import robot_experiment, robot_truth
from tests.helpers import perturbed_kinematic
from tests.independent_arm import UR6, urdf_text
from tests.urdf_reference import urdf_chain_fk

_FIRST = '<origin xyz="0 0 0.163" rpy="0 0 0"/>'  # the UR-type arm's first joint
# First joint origins (xyz [m], rpy [rad]) of the fixtures: the arm hung from its base
# link 38.8 mm off the origin with its first axis along -z (an SO-101-like base); turned
# 180 deg about z and 38.8 mm away; a KUKA KR210-like axis 2.8 mm off, slightly tilted.
MOUNTS = {
    "flipped": ("0.0388 0 0.0624", f"{np.pi!r} 0 0"),
    "turned": ("-0.0388 0.0012 0.0624", f"0 0 {np.pi!r}"),
    "tilted": ("0.00262 -0.000976 0.163", "0.002 -0.0013 0.4"),
}


def _fixture(tmp_path, which: str):
    xyz, rpy = MOUNTS[which]
    text = urdf_text(UR6, "ur6")
    assert _FIRST in text
    path = tmp_path / f"{which}.urdf"
    path.write_text(text.replace(_FIRST, f'<origin xyz="{xyz}" rpy="{rpy}"/>', 1))
    return path


def _import(path, tip="flange"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # tested in test_moved_base_fk_is_the_urdfs
        return robot_from_urdf(path, tip=tip)


def _poses(robot, n, seed=0):
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    rng = np.random.default_rng(seed)
    return rng.uniform(lim[:, 0], lim[:, 1], (n, robot.n_joints))


@pytest.mark.parametrize("which", sorted(MOUNTS))
def test_moved_base_fk_is_the_urdfs(which, tmp_path):
    """fk_flange equals the URDF's base -> flange to 1e-12 m (it was off by the base's
    shift and turn: 2 x 0.16 m and more for the flipped arm)."""
    path = _fixture(tmp_path, which)
    with pytest.warns(
        UserWarning,
        match=r"DH frame 0\) is base moved by .* kept as the robot's frame0: the robot "
        r"base stays link 'base'",
    ):
        robot = robot_from_urdf(path, tip="flange")
    assert not np.allclose(robot.T_base_0, np.eye(4))
    np.testing.assert_array_equal(robot.gravity, [0.0, 0.0, -9.80665])
    q = _poses(robot, 40)
    want = np.array([urdf_chain_fk(path, "base", "flange", qk) for qk in q])
    np.testing.assert_allclose(robot.fk_flange(q), want, rtol=0, atol=1e-12)
    if importlib.util.find_spec("yourdfpy") is not None:  # the dev venv has it
        import yourdfpy

        u = yourdfpy.URDF.load(str(path), load_meshes=False, build_scene_graph=True)
        for qk, T in zip(q[:8], robot.fk_flange(q[:8])):
            u.update_cfg(dict(zip(robot.joint_names, qk)))
            np.testing.assert_allclose(
                u.get_transform("flange", "base"), T, rtol=0, atol=1e-12
            )


VENDOR = Path(__file__).resolve().parents[1] / "data" / "vendor_urdf"


def _exact_quarters(text: str) -> str:
    """The vendor's rounded pi/2 and pi written exactly, as import-urdf reads them."""
    for rounded, k in (("-1.570796327 ", -1), ("3.1416 ", 2), ("1.5708 ", 1)):
        text = text.replace(rounded, f"{k * np.pi / 2!r} ")
    return text


@pytest.mark.parametrize(
    ("name", "base", "tip"),
    [
        ("kuka_kr210.urdf", "base_link", "tool0"),  # first axis 2.8 mm off
        ("kinova_gen3_7dof.urdf", "base_link", "end_effector_link"),  # along -z
    ],
)
def test_vendor_urdfs_pose_is_their_base_links(name, base, tip, tmp_path):
    """On the vendor files the nominal pose is tf's base_link -> tip (the Gen3's was
    2.2 m off: its base turned upside down)."""
    robot = _import(VENDOR / name, tip)
    assert robot.source.endswith("deg)") and "frame0: base_link moved" in robot.source
    exact = tmp_path / name
    exact.write_text(_exact_quarters((VENDOR / name).read_text()))
    q = _poses(robot, 20)
    want = np.array([urdf_chain_fk(exact, base, tip, qk) for qk in q])
    np.testing.assert_allclose(robot.fk_flange(q), want, rtol=0, atol=1e-12)


def test_fk_robot_command_gives_the_urdfs_pose(tmp_path, run_cli_here):
    """`kinecal fk --robot X.urdf` prints the base link -> flange pose (mm, W P R)."""
    path = _fixture(tmp_path, "flipped")
    robot = _import(path)
    for qk in _poses(robot, 3, seed=1):
        r = run_cli_here("fk", "--robot", path, "--json", "--", *np.degrees(qk))
        assert r.returncode == 0, r.stderr
        got = json.loads(r.stdout)
        want = urdf_chain_fk(path, "base", "flange", qk)
        np.testing.assert_allclose(got["flange_mm"], want[:3, 3] * 1e3, atol=1e-9)
        R = Rotation.from_euler("xyz", got["wpr_deg"], degrees=True).as_matrix()
        np.testing.assert_allclose(R, want[:3, :3], atol=1e-12)


def test_import_urdf_writes_frame0_that_reads_back(tmp_path, run_cli_here):
    path = _fixture(tmp_path, "tilted")
    out = tmp_path / "robot.yaml"
    r = run_cli_here("import-urdf", path, "--tip", "flange", "--out", out)
    assert r.returncode == 0, r.stderr
    doc = yaml.load(out.read_text())
    assert set(doc["frame0"]) == {"x", "y", "z", "r", "w", "p"}
    # Its origin: the first axis's point nearest the base link's origin [mm].
    xyz, rpy = (np.array(v.split(), float) for v in MOUNTS["tilted"])
    u = Rotation.from_euler("xyz", rpy).apply([0.0, 0.0, 1.0])
    got = [doc["frame0"][k] for k in "xyz"]
    np.testing.assert_allclose(got, (xyz - (xyz @ u) * u) * 1e3, rtol=0, atol=1e-9)
    robot = load_robot(out)
    q = _poses(robot, 20)
    want = np.array([urdf_chain_fk(path, "base", "flange", qk) for qk in q])
    # (the file's DH numbers are rounded to 1e-9 mm and deg: 1e-11 m at 0.6 m)
    np.testing.assert_allclose(robot.fk_flange(q), want, rtol=0, atol=2e-11)
    assert dump_robot(robot_from_dict(doc, "again")) == doc  # load -> dump -> load


@pytest.mark.parametrize(
    "frame0",
    [
        {"x": 38.8, "y": -1.2, "z": 62.4, "r": 180.0, "w": 0.0, "p": 180.0},
        {"x": 1e-7, "y": 0.0, "z": 0.0, "r": 0.0, "w": 1e-7, "p": 0.0},
        {"x": -500.0, "y": 20.0, "z": 3.0, "r": -30.0, "w": 90.0, "p": 12.0},
        {"z": 400.0},
    ],
)
@pytest.mark.parametrize("convention", ["dh", "mdh"])
def test_frame0_round_trip_and_fk(frame0, convention):
    """frame0 loads, dumps and loads again (mm, deg); the nominal pose is frame0 times
    the pose without it, for a standard and a Craig table."""
    base = dump_robot(load_robot("fanuc-lrmate200id"))
    base["convention"] = convention
    plain = robot_from_dict(base, "plain")
    assert "frame0" not in dump_robot(plain)  # a robot without one: files unchanged
    robot = robot_from_dict({**base, "frame0": frame0}, "with")
    doc = dump_robot(robot)
    again = robot_from_dict(yaml.load(yaml.dump(doc)), "again")
    np.testing.assert_allclose(again.T_base_0, robot.T_base_0, rtol=0, atol=1e-14)
    assert dump_robot(again) == doc
    want = {k: frame0.get(k, 0.0) for k in "xyzrwp"}
    got = doc["frame0"]
    if want["w"] != 90.0:  # (at w = 90 deg only r - p is defined)
        assert got == pytest.approx(want, abs=1e-9)
    q = _poses(plain, 10)
    np.testing.assert_allclose(
        robot.fk_flange(q), robot.T_base_0 @ plain.fk_flange(q), rtol=0, atol=1e-14
    )


def _in_metres(frame0: dict) -> dict:
    """The LR Mate's robot YAML in metres and degrees, with ``frame0``."""
    doc = dump_robot(load_robot("fanuc-lrmate200id"))
    doc["units"] = {"length": "m", "angle": "deg"}
    for row in doc["joints"]:
        row["d"], row["a"] = row["d"] / 1e3, row["a"] / 1e3
    for key in ("flange", "tool"):
        doc[key] = {k: v / 1e3 if k in "xyz" else v for k, v in doc[key].items()}
    return {**doc, "frame0": frame0}


@pytest.mark.parametrize(
    ("frame0", "angle", "message"),
    [
        ({"x": 0.0028}, "deg", None),
        ({"x": 2800.0}, "deg", r"frame0\.x: 2800 m is not a plausible offset of a "
         r"robot's frame 0 from its base \(over 100 m; units\.length is 'm'\); did you "
         r"mean 'mm'\?"),
        ({"r": 180.0}, "rad", r"frame0\.r: 180 rad is not a plausible angle \(over 2 "
         r"turns; units\.angle is 'rad'\); did you mean 'deg'\?"),
        ({"p": 900.0}, "deg", r"frame0\.p: 900 deg is not a plausible angle"),
        ({"rx": 90.0}, "deg", r"frame0: unknown key 'rx' \(allowed: p, r, w, x, y, z\)"),
        ({"z": "62 mm"}, "deg", r"frame0\.z: expected a number; got '62 mm'"),
        ([0, 0, 0.06], "deg", r"frame0: expected a mapping; got list"),
    ],
)  # fmt: skip
def test_frame0_is_validated_strictly(frame0, angle, message, tmp_path, run_cli_here):
    """A bad frame0 (unknown key, units slip, not a number) is refused with the file,
    the key and what was expected, exit 2 and no traceback (`fk --robot`)."""
    doc = _in_metres(frame0)
    if angle == "rad":
        doc["units"]["angle"] = "rad"
        for row in doc["joints"]:
            for k in ("theta_offset", "alpha"):
                row[k] = np.radians(row[k]).item()
            row["limits"] = np.radians(row["limits"]).tolist()
            if "velocity" in row:  # deg/s -> rad/s (450 rad/s is no joint's speed)
                row["velocity"] = np.radians(row["velocity"]).item()
        for key in ("flange", "tool"):
            doc[key] = {
                k: np.radians(v).item() if k in "rwp" else v
                for k, v in doc[key].items()
            }
    f = tmp_path / "robot.yaml"
    f.write_text(yaml.dump(doc))
    r = run_cli_here("fk", "--robot", f, "--json", "--", *["10"] * 6)
    if message is None:  # a plausible frame0 in metres
        assert r.returncode == 0, r.stderr
        return
    assert r.returncode == 2, r.stdout
    assert f"{f}" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert re.search(message, r.stderr), r.stderr


def _old_import(robot):
    """The description the previous import gave: the robot base moved onto the first
    axis (DH frame 0), gravity in that frame, no frame0."""
    R0 = robot.T_base_0[:3, :3]
    return replace(robot, T_base_0=np.eye(4), gravity=R0.T @ robot.gravity)


@pytest.mark.parametrize("which", ["flipped", "tilted"])
def test_calibration_is_the_same_with_the_base_link_as_robot_base(which, tmp_path):
    """The same data calibrated with the robot base at the URDF's base link (frame0)
    and moved onto the first axis (the previous import): the same held-out accuracy and
    parameters (the user frame -> joint 1 frame is fitted either way); the robot base
    in the user frame differs by frame0 exactly. A model file of the previous import
    (no frame0) reads back and evaluates alike."""
    robot = _import(_fixture(tmp_path, which))
    old = _old_import(robot)
    truth = robot_truth(robot, seed=3)
    exp = robot_experiment(truth, 2, n_train=50, n_test=120)
    new_res = calibrate(robot, exp.train, "full")
    old_res = calibrate(old, exp.train, "full")
    assert new_res.success and old_res.success
    new_m = evaluate(new_res.calibrated, exp.test).metrics
    old_m = evaluate(old_res.calibrated, exp.test).metrics
    assert new_m.rms_mm < 0.06  # the tracker's noise is ~0.02 mm
    assert abs(new_m.rms_mm - old_m.rms_mm) < 1e-7
    assert abs(new_m.max_mm - old_m.max_mm) < 1e-7
    # Parameters: the same, to where the solver stops (1e-9, or 1e-5 of their standard
    # deviation: a weakly determined link moment differs by 1e-7 of its 0.06).
    d = np.abs(new_res.params - old_res.params)
    std = np.nan_to_num(new_res.calibrated.std, nan=0.0)
    assert np.all((d < 1e-9) | (d < 1e-5 * std)), d / np.maximum(std, 1e-300)
    # The model base (joint 1 frame) in the robot base: the robot base reported in
    # the user frame (T_user_modelbase inv(this)) is the base link, where it was DH
    # frame 0.
    np.testing.assert_allclose(
        robot_base_offset(robot),
        robot.T_base_0 @ robot_base_offset(old),
        rtol=0,
        atol=1e-15,
    )
    f = save_model(tmp_path / "old.yaml", old_res.calibrated)
    assert "frame0" not in f.read_text()
    again = evaluate(load_model(f), exp.test).metrics  # (values written to 1e-15)
    assert abs(again.rms_mm - old_m.rms_mm) < 1e-12
    assert abs(again.max_mm - old_m.max_mm) < 1e-12


def test_exports_of_a_moved_base_model_keep_the_base_link(tmp_path, run_cli_here):
    """`export-urdf` (its `base` link), `--format yaml-dh` (with frame0) and `--like`:
    read back as robots, their flange is `fk --model`'s kinematic flange (in the base
    link) to 1e-9 mm; the nominal model --like the vendor's file gives the vendor's
    joint origins back."""
    path = _fixture(tmp_path, "flipped")
    robot = _import(path)
    f = save_model(tmp_path / "model.yaml", perturbed_kinematic(robot, 5))
    outs = {
        "urdf": tmp_path / "cal.urdf",
        "yaml-dh": tmp_path / "cal.yaml",
        "like": tmp_path / "like.urdf",
    }
    for fmt, out in outs.items():
        extra = ("--like", path) if fmt == "like" else ("--format", fmt)
        r = run_cli_here("export-urdf", f, *extra, "--out", out)
        assert r.returncode == 0, r.stderr
    assert "frame0:" in outs["yaml-dh"].read_text()
    for qk in _poses(robot, 3, seed=2):
        joints = [str(v) for v in np.degrees(qk)]
        want = run_cli_here("fk", "--model", f, "--json", "--", *joints)
        assert want.returncode == 0, want.stderr
        kin = json.loads(want.stdout)["kinematic"]
        for out in outs.values():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the base link moved onto the axis
                r = run_cli_here("fk", "--robot", out, "--json", "--", *joints)
            assert r.returncode == 0, r.stderr
            got = json.loads(r.stdout)
            np.testing.assert_allclose(got["flange_mm"], kin["flange_mm"], atol=1e-9)
            np.testing.assert_allclose(got["wpr_deg"], kin["wpr_deg"], atol=1e-9)
    # The nominal model --like the vendor's file: the vendor's own origins.
    nominal = perturbed_kinematic(robot, 5)
    nominal = replace(nominal, params=nominal.model.nominal.copy())
    g = save_model(tmp_path / "nominal.yaml", nominal)
    out = tmp_path / "nominal_like.urdf"
    r = run_cli_here("export-urdf", g, "--like", path, "--out", out)
    assert r.returncode == 0, r.stderr
    q = _poses(robot, 10, seed=3)
    for qk in q:
        np.testing.assert_allclose(
            urdf_chain_fk(out, "base", "flange", qk),
            urdf_chain_fk(path, "base", "flange", qk),
            rtol=0,
            atol=1e-12,
        )


def test_dh_description_of_a_moved_base_model_keeps_frame0(tmp_path):
    """`kinecal.compensation.dh_description`: the robot base it returns in the user
    frame is the base link, and its description keeps frame0, so that the two give the
    model's kinematic tool point (it lacked frame0: off by the base's shift and turn)."""
    from kinecal.compensation import dh_description, kinematic_params
    from kinecal.models import ModelInputs

    robot = _import(_fixture(tmp_path, "turned"))
    cal = perturbed_kinematic(robot, 5)
    desc, T_user_base = dh_description(cal)
    np.testing.assert_array_equal(desc.T_base_0, robot.T_base_0)
    q = _poses(robot, 10, seed=4)
    want = cal.model.evaluate(kinematic_params(cal), ModelInputs.make(q)).p_user
    got = (T_user_base @ desc.fk_tool(q))[:, :3, 3]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def _origins(text: str) -> np.ndarray:
    """Every ``<origin xyz rpy>`` of a URDF text, (k, 6) [m, rad]."""
    found = re.findall(r'<origin xyz="([^"]*)" rpy="([^"]*)"', text)
    return np.array([[float(v) for v in f"{a} {b}".split()] for a, b in found])


@pytest.mark.parametrize(
    ("name", "tip"),
    [("kuka_kr210.urdf", "tool0"), ("kinova_gen3_7dof.urdf", "end_effector_link")],
)
def test_like_copy_does_not_depend_on_frame0(name, tip):
    """`export-urdf --like` writes the vendor's frames: one calibration (the same
    parameters: user frame -> joint 1 frame, joint rows, tool) of the robot imported with
    frame0 and of the robot with its base moved onto the first axis (the previous
    import) gives the same copy to 1e-15 m (a model file written before reads as the
    latter)."""
    from kinecal.workflows import export_model

    robot = _import(VENDOR / name, tip)
    new = perturbed_kinematic(robot, 5)
    old_model = CalibrationModel(_old_import(robot), ModelSpec.preset("kinematic"))
    old = CalibratedModel(old_model, new.params, new.std, list(new.status))
    texts = [
        export_model(c, "urdf", like=str(VENDOR / name), user_link="user").text
        for c in (new, old)
    ]
    a, b = (_origins(t) for t in texts)  # the joints', the user and tool links', ...
    assert a.shape == b.shape and a.shape[0] >= robot.n_joints + 2
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-15)
    strip = re.compile(r'<origin xyz="[^"]*" rpy="[^"]*"/>')
    assert strip.sub("", texts[0]) == strip.sub("", texts[1])  # the rest as it was
