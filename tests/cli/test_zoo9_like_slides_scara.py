"""`export-urdf --like` on robots whose axes the vendor's file places freely: a slide
(prismatic joint) whose URDF origin is off the line the DH table puts it on (a track
under an arm, the track's joint 300 mm above the root), and a SCARA whose axes are all
parallel (its base is placed by the perpendiculars between its turning axes). Both were
refused before ("300 mm from the nominal axes", "all joint axes are parallel"). The
URDFs are written here from the numbers: the arm is the UR5e of Universal Robots' DH
page (d1 162.5, a2 -425, a3 -392.2, d4 133.3, d5 99.7, d6 99.6 mm), the SCARA made up."""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinecal.io import save_model
from kinecal.robot import robot_from_urdf
from tests.cli_contract import run_kinecal
from tests.helpers import perturbed_kinematic
from tests.urdf_reference import urdf_chain_fk

_H = math.pi / 2


def _joint(name, kind, parent, child, xyz, rpy="0 0 0", axis="0 0 1", lim=(-3, 3)):
    limit = f'<limit lower="{lim[0]}" upper="{lim[1]}" effort="1" velocity="1"/>'
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
        f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>'
        f'<axis xyz="{axis}"/>{limit if kind != "fixed" else ""}</joint>'
    )


def _urdf(name: str, joints: list[str]) -> str:
    links = {p for j in joints for p in j.split('link="')[1:]}
    names = sorted({x.split('"')[0] for x in links})
    body = "".join(f'<link name="{n}"/>' for n in names) + "".join(joints)
    return f'<?xml version="1.0"?><robot name="{name}">{body}</robot>\n'


def _track_ur5e() -> str:
    ur = [
        ("0 0 0.1625", "0 0 0"), ("0 0 0", f"{_H} 0 0"), ("-0.425 0 0", "0 0 0"),
        ("-0.3922 0 0.1333", "0 0 0"), ("0 -0.0997 0", f"{_H} 0 0"),
        ("0 0.0996 0", f"{-_H} 0 0"),
    ]  # fmt: skip
    js = [
        _joint("track", "prismatic", "world", "l0", "0 0 0.3", axis="1 0 0", lim=(0, 3))
    ]
    js += [
        _joint(f"j{i + 1}", "revolute", f"l{i}", f"l{i + 1}", *o)
        for i, o in enumerate(ur)
    ]
    js.append(_joint("tool0_fixed", "fixed", "l6", "tool0", "0 0 0.05"))
    return _urdf("track_ur5e", js)


def _scara() -> str:
    return _urdf("scara", [
        _joint("j1", "revolute", "base", "arm1", "0 0 0.4"),
        _joint("j2", "revolute", "arm1", "arm2", "0.3 0 0"),
        _joint("j3", "prismatic", "arm2", "quill", "0.25 0 0", axis="0 0 -1", lim=(0, 0.2)),
        _joint("j4", "revolute", "quill", "tool", "0 0 -0.1"),
    ])  # fmt: skip


@pytest.mark.parametrize(
    ("make", "base", "tip"), [(_track_ur5e, "world", "tool0"), (_scara, "base", "tool")]
)
def test_zoo9_like_export_of_slides_and_parallel_axes(
    make, base, tip, tmp_path, capsys
):
    src = tmp_path / "vendor.urdf"
    src.write_text(make())
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the base turned into frame0: reported
        robot = robot_from_urdf(src)
    cal = perturbed_kinematic(robot, 5)
    f = save_model(tmp_path / "model.yaml", cal)
    out = tmp_path / "cal.urdf"
    res = run_kinecal(capsys, "export-urdf", f, "--like", src, "--out", out)
    assert res.code == 0, str(res)
    lim = robot.limits
    for q in np.random.default_rng(2).uniform(
        lim[:, 0], lim[:, 1], (3, robot.n_joints)
    ):
        ctrl = np.where(robot.prismatic, q * 1e3, np.degrees(q))
        m = run_kinecal(capsys, "fk", "--model", f, "--json", "--", *map(str, ctrl))
        assert m.code == 0, str(m)
        want = np.array(json.loads(m.out)["kinematic"]["flange_mm"])
        got = urdf_chain_fk(Path(out), base, tip, q)[:3, 3] * 1e3
        assert np.abs(got - want).max() < 1e-4
