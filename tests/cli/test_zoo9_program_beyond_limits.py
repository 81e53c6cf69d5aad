"""A KUKA program's home position (A2 -90 deg, the wrist straight at A5 0 deg) on the
ROS-Industrial KR210 URDF, whose J2 counts from another zero (limits -45..85 deg): the
target is reachable only beyond J2's limit. It was reported 'unreachable: predicted
error 384 mm' or blamed on J4 (the solve without limits, started from the limited
solution, at a singular wrist converged too slowly to count); it is blamed on J2 as the
same target with the wrist bent is."""

from __future__ import annotations

import warnings
from pathlib import Path

from kinecal.io import save_model
from kinecal.robot import robot_from_urdf
from tests.cli_contract import run_kinecal
from tests.helpers import perturbed_kinematic

KR210 = Path(__file__).resolve().parents[1] / "data" / "vendor_urdf" / "kuka_kr210.urdf"

_AXIS = "A1 0.0,A2 -90.0,A3 90.0,A4 0.0,A5 {a5},A6 0.0"
_DAT = "DEFDAT  HOME\nDECL E6AXIS XHOME1={{{0}}}\nDECL E6AXIS XBENT={{{1}}}\nENDDAT\n"


def test_zoo9_program_target_beyond_a_limit_at_a_singular_wrist(tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the first axis off base_link's z: reported
        robot = robot_from_urdf(KR210)
    cal = perturbed_kinematic(robot, 3, 2e-4)
    f = save_model(tmp_path / "model.yaml", cal)
    prog = tmp_path / "home.dat"
    prog.write_text(_DAT.format(_AXIS.format(a5="0.0"), _AXIS.format(a5="10.0")))
    res = run_kinecal(
        capsys, "compensate", prog, "--model", f, "--format", "krl",
        "--out", tmp_path / "out.dat", "-q",
    )  # fmt: skip
    assert res.code != 0 and not (tmp_path / "out.dat").exists()
    for line, name in ((2, "XHOME1"), (3, "XBENT")):
        assert f"line {line} ({name}): joint_limit (J2 beyond its limit)" in res.err
    assert "): unreachable" not in res.err
