"""URDF import: the DH description reproduces the URDF chain exactly (checked with the
independent evaluator in tests/urdf_reference.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import ConfigError
from kinecal.robot import load_robot, robot_from_urdf
from tests.urdf_reference import urdf_chain_fk

DATA = Path(__file__).resolve().parents[1] / "data" / "fanuc_lrmate200id"


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


@pytest.mark.parametrize(
    ("file", "tip"),
    [
        ("fanuc_lrmate200id.urdf", "fanuc_flange"),
        ("fanuc_lrmate200id7l.urdf", "flange"),
        ("rosi_lrmate200id.urdf", "tool0"),
        ("rosi_lrmate200id7l.urdf", "tool0"),
    ],
)
def test_fanuc_urdfs(file, tip, rng):
    robot = robot_from_urdf(DATA / file, base="base_link", tip=tip)
    q = rng.uniform(-2.0, 2.0, size=(50, robot.n_joints))
    want = np.array([urdf_chain_fk(DATA / file, "base_link", tip, qq) for qq in q])
    np.testing.assert_allclose(robot.fk_flange(q), want, atol=1e-12)


def _joint(name, parent, child, kind, xyz, rpy, axis):
    lim = (
        '<limit lower="-2" upper="2" effort="1" velocity="1"/>'
        if kind != "fixed"
        else ""
    )
    ax = f'<axis xyz="{axis}"/>' if kind != "fixed" else ""
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
        f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>{ax}{lim}</joint>'
    )


# URDF axes are unit vectors; a slanted one for the prismatic joint.
_SLIDE = " ".join(f"{v:.17g}" for v in np.array([0.3, 0.1, 1.0]) / np.sqrt(1.1))
GENERAL = (
    '<robot name="odd">'
    + "".join(f'<link name="l{i}"/>' for i in range(9))
    + _joint("j1", "l0", "l1", "revolute", "0 0 0.2", "0 0 0.3", "0 0 1")
    + _joint("j2", "l1", "l2", "prismatic", "0.1 0.02 0.05", "0.2 -0.4 0.1", _SLIDE)
    + _joint("j3", "l2", "l3", "revolute", "0.3 0 0", "1.2 0.1 -0.3", "0 1 0")
    + _joint("j4", "l3", "l4", "continuous", "0.25 0 0", "0 0 0", "0 1 0")
    + _joint("f1", "l4", "l5", "fixed", "0.05 0.01 0", "0 0.3 0", "")
    + _joint("j5", "l5", "l6", "revolute", "0 0 0.1", "0 0 0", "0 0 -1")
    + _joint("j6", "l6", "l7", "revolute", "0 0 0.12", "0.5 0 0", "0 0 1")
    + _joint("tip", "l7", "l8", "fixed", "0.01 0.02 0.08", "0.1 0.2 0.3", "")
    + "</robot>"
)


def test_skew_parallel_collinear_and_prismatic_axes(tmp_path, rng):
    f = tmp_path / "odd.urdf"
    f.write_text(GENERAL)
    robot = robot_from_urdf(f)
    assert robot.name == "odd" and robot.n_joints == 6
    assert [j.kind for j in robot.joints][:2] == ["revolute", "prismatic"]
    assert np.isinf(robot.joints[3].limits).all()  # continuous
    q = rng.uniform(-2.0, 2.0, size=(50, 6))
    want = np.array([urdf_chain_fk(f, "l0", "l8", qq) for qq in q])
    np.testing.assert_allclose(robot.fk_flange(q), want, atol=1e-12)
    # load_robot reads URDF files too
    np.testing.assert_allclose(load_robot(f).fk_flange(q), want, atol=1e-12)


def test_bad_urdfs(tmp_path):
    branch = tmp_path / "branch.urdf"
    branch.write_text(
        '<robot name="b">'
        + "".join(f'<link name="{k}"/>' for k in "abcd")
        + _joint("j1", "a", "b", "revolute", "0 0 0", "0 0 0", "0 0 1")
        + _joint("j2", "a", "c", "revolute", "0 0 0", "0 0 0", "0 0 1")
        + _joint("j3", "c", "d", "revolute", "0.1 0 0", "0 0 0", "0 1 0")
        + "</robot>"
    )
    with pytest.raises(ConfigError, match="branches at link 'a'"):
        robot_from_urdf(branch)
    with pytest.warns(UserWarning, match="has 2 of the file's 3 movable joints"):
        assert robot_from_urdf(branch, tip="d").n_joints == 2
    tilted = tmp_path / "tilted.urdf"
    tilted.write_text(
        '<robot name="t"><link name="a"/><link name="b"/>'
        + _joint("j1", "a", "b", "revolute", "0 0 0", "0 0 0", "1 0 0")
        + "</robot>"
    )
    with pytest.raises(ConfigError, match="first joint axis must be the base"):
        robot_from_urdf(tilted)
    with pytest.raises(ConfigError, match="no link 'nowhere'"):
        robot_from_urdf(DATA / "rosi_lrmate200id.urdf", tip="nowhere")
    broken = tmp_path / "broken.urdf"
    broken.write_text("<robot name='x'><link")
    with pytest.raises(ConfigError, match="cannot read URDF"):
        robot_from_urdf(broken)


def test_import_urdf_command(tmp_path, run_cli):
    out = tmp_path / "lrmate.yaml"
    src = DATA / "rosi_lrmate200id.urdf"
    r = run_cli("import-urdf", str(src), "--tip", "tool0", "--out", str(out))
    assert r.returncode == 0, r.stderr
    again = run_cli("import-urdf", str(src), "--tip", "tool0", "--out", str(out))
    assert again.returncode == 2 and "--force" in again.stderr
    a = load_robot(out)
    b = robot_from_urdf(src, tip="tool0")
    q = np.linspace(-1, 1, 36).reshape(6, 6)
    np.testing.assert_allclose(a.fk_flange(q), b.fk_flange(q), atol=1e-11)


def test_lifting_column_off_the_base_origin(tmp_path, rng):
    """A prismatic first joint (a torso lift) need not pass through the base origin."""
    f = tmp_path / "lift.urdf"
    f.write_text(
        '<robot name="lift">'
        + "".join(f'<link name="l{i}"/>' for i in range(4))
        + _joint("torso", "l0", "l1", "prismatic", "-0.06 0.02 0.8", "0 0 0", "0 0 1")
        + _joint("arm1", "l1", "l2", "revolute", "0.15 0.03 0.1", "0 0 1.0", "0 0 1")
        + _joint("arm2", "l2", "l3", "revolute", "0.12 0 0", "1.57 0 0", "0 0 1")
        + "</robot>"
    )
    robot = robot_from_urdf(f)
    q = rng.uniform(-1.0, 1.0, size=(30, 3))
    want = np.array([urdf_chain_fk(f, "l0", "l3", qq) for qq in q])
    np.testing.assert_allclose(robot.fk_flange(q), want, atol=1e-12)


def test_a_urdf_in_millimetres_is_refused(tmp_path, capsys):
    """URDF lengths are metres: a file written in mm (every origin 1000x) is refused by
    every reader of URDFs, naming the file and the longest origin (it was read as a
    robot kilometres long, and import-urdf failed with an internal error)."""
    import re

    from tests.cli_contract import failed_with, run_kinecal
    from tests.independent_arm import urdf_text

    good = urdf_text()
    mm = re.sub(
        r'xyz="([^"]*)"',
        lambda m: 'xyz="{}"'.format(
            " ".join(f"{float(v) * 1e3:g}" for v in m.group(1).split())
        ),
        re.sub(r"<axis[^>]*/>", lambda m: m.group(0).replace("xyz", "AXIS"), good),
    ).replace("AXIS", "xyz")
    assert mm != good
    f = tmp_path / "arm_mm.urdf"
    f.write_text(mm)
    with pytest.raises(ConfigError, match=r"arm_mm.urdf: the joint origins add up to"):
        robot_from_urdf(f, tip="flange")
    (tmp_path / "arm.urdf").write_text(good)
    assert robot_from_urdf(tmp_path / "arm.urdf", tip="flange").n_joints == 7
    for args in (
        ("import-urdf", f, "--tip", "flange", "--out", tmp_path / "arm.yaml"),
        ("fk", "--robot", f, "--", *["0"] * 7),
    ):
        res = run_kinecal(capsys, *map(str, args))
        failed_with(res, "arm_mm.urdf", "millimetres")
    assert not (tmp_path / "arm.yaml").exists()
