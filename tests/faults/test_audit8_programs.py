"""Audit 8: a RAPID jointtarget (or KRL axis aggregate) written in radians. Both formats
hold degrees (ABB's robjoint: each axis "in degrees from the calibration position"); the
radians were read as degrees, a pose within 6.3 deg of every joint's zero, and the
program was "compensated" and written back with exit 0."""

from __future__ import annotations

import numpy as np

from tests.cli_contract import failed_with, run_kinecal

_EAX = "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]"


def _module(*targets: list[float]) -> str:
    lines = ["MODULE M"]
    for k, q in enumerate(targets):
        vals = ",".join(f"{v:.4f}" for v in q)
        lines.append(f"    CONST jointtarget j{k}:=[[{vals}],{_EAX}];")
    lines += ["    PROC main()"]
    lines += [
        f"        MoveAbsJ j{k}\\NoEOffs, v500, fine, tool0;"
        for k in range(len(targets))
    ]
    return "\n".join([*lines, "    ENDPROC", "ENDMODULE", ""])


def test_rapid_joint_targets_in_radians_are_refused(data, tmp_path, capsys):
    q_deg = np.array(
        [[10.0, -20.0, 35.0, 5.0, -60.0, 30.0], [-25.0, 15.0, 20.0, 0, 45.0, -10]]
    )
    prog = tmp_path / "rad.mod"
    prog.write_text(_module(*np.radians(q_deg)))
    out = tmp_path / "out.mod"
    res = run_kinecal(
        capsys, "compensate", prog, "--model", data["model"], "--out", out
    )
    failed_with(res, f"{prog}: line 2: j0:", "looks like radians", "holds degrees")
    assert not out.exists()
    # the same targets in degrees are compensated
    prog.write_text(_module(*q_deg))
    res = run_kinecal(
        capsys, "compensate", prog, "--model", data["model"], "--out", out
    )
    assert res.code == 0 and "radians" not in res.err, str(res)


def test_one_pose_near_zero_is_a_warning_a_home_pose_is_not(data, tmp_path, capsys):
    prog = tmp_path / "one.mod"
    prog.write_text(_module([0.1745, -0.3491, 0.6109, 0.0, -1.0472, 0.5236]))
    out = tmp_path / "out.mod"
    res = run_kinecal(
        capsys, "compensate", prog, "--model", data["model"], "--out", out
    )
    assert res.code == 0, str(res)
    assert "looks like radians" in res.err and "read as degrees" in res.err, res.err
    # whole degrees near zero (a home pose, a joint jogged from it): nothing to say
    prog.write_text(_module([0, 0, 0, 0, -1, 0], [0, 0, 0, 0, -1, 5]))
    res = run_kinecal(
        capsys, "compensate", prog, "--model", data["model"], "--out", out, "--force"
    )
    assert res.code == 0 and "radians" not in res.err, str(res)


def test_extrapolation_names_the_program_line(data, tmp_path, capsys):
    """A program's targets beyond the calibrated ranges were named 'row 1 J3' (their
    order among the targets): the line and the target's name say where they are."""
    prog = tmp_path / "p.mod"
    prog.write_text(_module([10, -20, 35, 5, -60, 30], [0, 0, 0, 0, 30, 0]))
    out = tmp_path / "out.mod"
    res = run_kinecal(
        capsys, "compensate", prog, "--model", data["model"], "--out", out
    )
    assert res.code == 0, str(res)
    warned = [ln for ln in res.err.splitlines() if "outside the joint ranges" in ln]
    assert warned and f"{prog}: " in warned[0], res.err
    assert "line 3 (j1) J" in warned[0] and "row " not in warned[0], warned[0]
