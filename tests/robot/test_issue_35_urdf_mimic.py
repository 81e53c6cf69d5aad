"""URDF mimic joints read as a coupling, kinecal's own exports accepted as --robot
(issue 35 point 6, issue 34)."""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import ConfigError
from kinecal.identification import calibrate
from kinecal.io import save_model, write_measurements
from kinecal.robot import load_robot, robot_from_urdf
from kinecal.simulation import LaserTracker, experiment2
from tests.cli_contract import run_kinecal as _cli

DATA = Path(__file__).resolve().parents[1] / "data"
ROSI = DATA / "fanuc_lrmate200id" / "rosi_lrmate200id.urdf"
UR10E = DATA / "ur_e_series" / "ur10e_like_ur_description.urdf"


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A kinematic LR Mate model, its training data, and kinecal's three URDF exports
    of it (joints in kinematic angles, --coupling mimic, --like the ROS-I file)."""
    from kinecal.cli import main

    d = tmp_path_factory.mktemp("mimic")
    e = experiment2(5, n_train=60, tracker=LaserTracker(5e-6, 0.0))
    save_model(
        d / "model.yaml", calibrate(e.truth.robot, e.train, "kinematic").calibrated
    )
    write_measurements(d / "train.csv", e.train, e.truth.robot)
    for name, extra in (
        ("kin", ()),
        ("mimic", ("--coupling", "mimic")),
        ("like", ("--like", str(ROSI), "--user-link", "user")),
    ):
        code = main(
            [
                "export-urdf",
                str(d / "model.yaml"),
                "--out",
                str(d / f"{name}.urdf"),
                *extra,
            ]
        )
        assert code == 0
    return d


def _q(robot, n=8, seed=4):
    lim = np.where(np.isfinite(robot.limits), robot.limits, [-np.pi, np.pi])
    return np.random.default_rng(seed).uniform(
        lim[:, 0], lim[:, 1], (n, robot.n_joints)
    )


def test_issue_35_mimic_export_imports_with_the_coupling_and_fk_equals_the_model(
    capsys, exported
):
    """--coupling mimic -> import-urdf: 6 joints, theta3 = J3 + J2, and `fk --robot
    FILE.urdf` at controller angles equals `fk --model`'s kinematic flange."""
    r = robot_from_urdf(exported / "mimic.urdf")
    assert r.n_joints == 6
    np.testing.assert_allclose(r.coupling, load_robot("fanuc-lrmate200id").coupling)
    assert [j.name for j in r.joints] == [f"j{i}" for i in range(1, 7)]
    out = exported / "mimic.yaml"
    code, _, err = _cli(
        capsys, "import-urdf", str(exported / "mimic.urdf"), "--out", str(out)
    )
    assert code == 0, err
    for qk in np.degrees(_q(r, 5)):
        args = ["--json", "--", *map(str, qk)]
        c1, o1, e1 = _cli(capsys, "fk", "--robot", str(exported / "mimic.urdf"), *args)
        c2, o2, e2 = _cli(capsys, "fk", "--model", str(exported / "model.yaml"), *args)
        c3, o3, e3 = _cli(capsys, "fk", "--robot", str(out), *args)
        assert c1 == c2 == c3 == 0, (e1, e2, e3)
        want = json.loads(o2)["kinematic"]["flange_mm"]
        for got in (o1, o3):
            assert np.abs(np.subtract(json.loads(got)["flange_mm"], want)).max() < 1e-6


def test_issue_35_mimic_fk_agrees_with_pinocchio(exported):
    """The imported robot's flange equals pinocchio's mimic-aware FK of the file."""
    pin = pytest.importorskip("pinocchio", reason="pinocchio (pip install pin) absent")
    text = (exported / "mimic.urdf").read_text()
    model = pin.buildModelFromXML(text, mimic=True)
    data = model.createData()
    r = robot_from_urdf(exported / "mimic.urdf")
    base, flange = (model.getFrameId(f, pin.FrameType.BODY) for f in ("base", "flange"))
    idx = [model.joints[model.getJointId(f"j{i + 1}")].idx_q for i in range(6)]
    for q in _q(r):
        qp = np.zeros(model.nq)
        qp[idx] = q
        pin.framesForwardKinematics(model, data, qp)
        T = data.oMf[base].inverse() * data.oMf[flange]
        np.testing.assert_allclose(r.fk_flange(q), T.homogeneous, atol=1e-12)


def test_issue_35_own_exports_are_accepted_as_robot(capsys, exported, tmp_path):
    """Root 'user' and tip 'flange' (or the vendor's tip) recognised: fk, calibrate and
    plan --robot take every kind of URDF kinecal writes."""
    for name, base_frame, tip in (
        ("kin", "base", "flange"),
        ("mimic", "base", "flange"),
        ("like", "base_link", "tool0"),
    ):
        f = exported / f"{name}.urdf"
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            r = robot_from_urdf(f)
        assert f"URDF {base_frame} -> {tip})" in r.source, r.source
        # every file takes the controller angles: the coupling read back (mimic joints,
        # or the 'kinecal coupling' line of a file whose joints are kinematic angles)
        np.testing.assert_allclose(r.coupling, load_robot("fanuc-lrmate200id").coupling)
        shift = (
            [0.0, 0.0, 330.0] if name == "like" else [0.0, 0.0, 0.0]
        )  # ROS-I base_link
        for qk in np.degrees(_q(load_robot("fanuc-lrmate200id"), 3)):
            args = ["--json", "--", *map(str, qk)]
            c1, o1, e1 = _cli(capsys, "fk", "--robot", str(f), *args)
            c2, o2, e2 = _cli(
                capsys, "fk", "--model", str(exported / "model.yaml"), *args
            )
            assert c1 == c2 == 0, (e1, e2)
            got = np.subtract(json.loads(o1)["flange_mm"], shift)
            want = json.loads(o2)["kinematic"]["flange_mm"]
            assert np.abs(got - want).max() < 1e-6, name
    # calibrate on the mimic export: controller angles, the coupling read from the
    # file; the fit is as good as with the built-in robot (the data's own twin).
    fits = {}
    for name, robot in (
        ("urdf", str(exported / "mimic.urdf")),
        ("builtin", "fanuc-lrmate200id"),
    ):
        code, said, err = _cli(
            capsys,
            "calibrate",
            str(exported / "train.csv"),
            "--robot",
            robot,
            "--model",
            "kinematic",
            "--out",
            str(tmp_path / name),
        )
        assert code == 0, err
        fits[name] = float(re.search(r"after +RMS ([0-9.]+) mm", said + err).group(1))
    assert fits["urdf"] < 0.05 and abs(fits["urdf"] - fits["builtin"]) < 1e-3, fits


def _urdf(tmp_path, joints: str) -> Path:
    links = "".join(f'<link name="{k}"/>' for k in ("a", "b", "c", "d", "e"))
    f = tmp_path / "m.urdf"
    f.write_text(f'<robot name="m">{links}{joints}</robot>')
    return f


def _j(name, parent, child, xyz="0 0 0", axis="0 0 1", mimic=""):
    return (
        f'<joint name="{name}" type="revolute"><parent link="{parent}"/>'
        f'<child link="{child}"/><origin xyz="{xyz}" rpy="0 0 0"/><axis xyz="{axis}"/>'
        f'<limit lower="-3" upper="3" effort="1" velocity="1"/>{mimic}</joint>'
    )


def test_issue_35_mimic_joints_that_do_not_fit_are_refused(tmp_path):
    ok = _urdf(
        tmp_path,
        _j("j1", "a", "b")
        + _j("j2", "b", "c", "0 0 0.3", "0 1 0")
        + _j(
            "m3",
            "c",
            "d",
            "0.4 0 0",
            "0 -1 0",
            '<mimic joint="j2" multiplier="2" offset="0.1"/>',
        )
        + _j("j3", "d", "e", "0 0 0", "0 1 0"),
    )
    r = robot_from_urdf(ok)
    assert r.n_joints == 3
    np.testing.assert_allclose(r.coupling, [[1, 0, 0], [0, 1, 0], [0, -2, 1]])
    # FK against the chain evaluated by hand: the mimic turns -(2 q2 + 0.1) about +y.
    from tests.urdf_reference import urdf_chain_fk

    for q in _q(r, 4):
        q4 = np.array([q[0], q[1], 2 * q[1] + 0.1, q[2]])
        want = urdf_chain_fk(ok, "a", "e", q4)
        np.testing.assert_allclose(r.fk_flange(q), want, atol=1e-12)
    declared = _urdf(
        tmp_path,
        _j("j1", "a", "b")
        + _j("j2", "b", "c", "0 0 0.3", "0 1 0")
        + _j("j3", "c", "d", "0.4 0 0", "0 1 0"),
    )
    text = declared.read_text()
    for line, words in (
        ("J3 += 1.0 * J2", None),
        ("J3 += x * J2", "cannot read the coupling term"),
        ("J3 += 1.0 * J9", "expected joints 1..3"),
        ("J3 += -1.0 * J3", "expected joints 1..3, two different"),
    ):
        declared.write_text(
            f"<!-- kinecal coupling (theta = C q_ctrl): {line} -->\n{text}"
        )
        if words is None:
            np.testing.assert_allclose(
                robot_from_urdf(declared).coupling, [[1, 0, 0], [0, 1, 0], [0, 1, 1]]
            )
        else:
            with pytest.raises(ConfigError, match=re.escape(words)):
                robot_from_urdf(declared)
    for joints, words in (
        (
            _j("j1", "a", "b")
            + _j("j2", "b", "c", "0 0 0.3", "0 1 0", '<mimic joint="nope"/>')
            + _j("j3", "c", "d", "0.4 0 0", "0 1 0"),
            "mimics 'nope'",
        ),
        (
            _j("j1", "a", "b")
            + _j("j2", "b", "c", "0 0 0.3", "0 1 0")
            + _j("m3", "c", "d", "0.4 0 0", "0 1 0", '<mimic joint="j2"/>')
            + _j("j3", "d", "e", "0.2 0 0", "0 1 0"),
            "turns about its own axis",
        ),
        (
            _j("j1", "a", "b")
            + _j("j2", "b", "c", "0 0 0.3", "0 1 0")
            + _j(
                "m3", "c", "d", "0.4 0 0", "0 1 0", '<mimic joint="j2" multiplier="x"/>'
            )
            + _j("j3", "d", "e", "0 0 0", "0 1 0"),
            "expected numbers",
        ),
        (
            _j("j1", "a", "b")
            + _j("j2", "b", "c", "0 0 0.3", "0 1 0")
            + _j(
                "m3", "c", "d", "0.4 0 0", "0 1 0", '<mimic joint="j2" multiplier="0"/>'
            )
            + _j("j3", "d", "e", "0 0 0", "0 1 0"),
            "non-zero multiplier",
        ),
    ):
        with pytest.raises(ConfigError, match=words):
            robot_from_urdf(_urdf(tmp_path, joints))


def test_issue_35_fixed_side_branches_do_not_stop_the_chain():
    """ur_description's base_link has the fixed frame 'base' beside the arm: the chain
    follows the arm without --tip and ends at tool0."""
    r = robot_from_urdf(UR10E)
    assert r.n_joints == 6 and "URDF world -> tool0" in r.source
