"""Issue 34: FANUC position registers. A program moving to ``PR[n]`` takes its values from
the controller; with its ``POSREG.VA`` the registers it moves to are corrected (a joint
register as a joint target, a Cartesian one in the UFRAME_NUM / UTOOL_NUM the program
selected before the motion) and written as a TP program that sets them. Checked through
the stand-in nominal controller of the Cartesian tests: the calibrated robot reaches the
taught poses."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.compensation._configs import encode_config
from kinecal.errors import DataError
from kinecal.io._fanuc_registers import read_position_registers, register_motions
from tests.compensation.test_issue_34_cartesian import (
    T_TOOL,
    T_UF,
    _controller,
    _numbers,
    _read_pose,
    _taught,
)

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


@pytest.fixture(scope="module")
def model_file(tracker_twin, tmp_path_factory):
    from kinecal.io import save_model

    return save_model(
        tmp_path_factory.mktemp("pr34") / "model.yaml", tracker_twin.calibrated
    )


def _va_number(v: float) -> str:
    s = f"{v:9.3f}"  # as the controller prints: no leading zero before the point
    return s.replace("-0.", " -.").replace(" 0.", "  .")


def _posreg(cal, q_joint, q_cart, T_cart) -> str:
    out = [
        "[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,20] OF Position Reg"
    ]
    for i, q in enumerate(q_joint, 1):
        d = np.degrees(q)
        out += [
            f"    [1,{i}] =   'J{i}'   Group: 1",
            "  " + "   ".join(f"J{j} = {_va_number(d[j - 1])} deg" for j in (1, 2, 3)),
            "  " + "   ".join(f"J{j} = {_va_number(d[j - 1])} deg" for j in (4, 5, 6)),
            "",
        ]
    flags = encode_config(cal, "fanuc-ls", q_cart)
    for i, (T, f) in enumerate(zip(T_cart, flags, strict=True), len(q_joint) + 1):
        x, y, z, w, p, r = _numbers("fanuc-ls", T)
        out += [
            f"    [1,{i}] =   'C{i}' ",
            f"  Group: 1   Config: {f[0]} {f[1]} {f[2]}, {f[3]}, {f[4]}, {f[5]}",
            f"  X: {_va_number(x)}   Y: {_va_number(y)}   Z: {_va_number(z)}",
            f"  W: {_va_number(w)}   P: {_va_number(p)}   R: {_va_number(r)}",
            "  EXT1:  ******** mm  ",
        ]
    out.append("    [1,19] =   '' Uninitialized")
    return "\r\n".join(out) + "\r\n"


def _program(n_joint: int, n_cart: int) -> str:
    mn = ["UFRAME_NUM=1 ;", "UTOOL_NUM=1 ;"]
    mn += [f"J PR[{i}:J{i}] 100% FINE ;" for i in range(1, n_joint + 1)]
    mn += [
        f"L PR[{i}] 200mm/sec CNT50 ;" for i in range(n_joint + 1, n_joint + n_cart + 1)
    ]
    mn += ["L PR[19] 100mm/sec FINE ;", "J PR[R[7]] 100% FINE ;"]
    mn += ["UFRAME_NUM=R[3] ;", f"L PR[{n_joint + n_cart + 1}] 200mm/sec FINE ;"]
    lines = [f"{i:4d}:{ln}" for i, ln in enumerate(mn, 1)]
    return "\r\n".join(["/PROG  PRS", "/MN", *lines, "/POS", "/END", ""])


def _assignments(text: str) -> dict[int, dict[int, float]]:
    """PR[i,j]=value lines of a TP program, read with this test's own expression."""
    out: dict[int, dict[int, float]] = {}
    for i, j, v in re.findall(rf"PR\[(\d+),(\d+)\]=\(?({_NUM})\)? ;", text):
        out.setdefault(int(i), {})[int(j)] = float(v)
    return out


def test_issue_34_position_registers_corrected_through_the_nominal_controller(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    rng = np.random.default_rng(341)
    q_joint, q_cart = _taught(rng, 3), _taught(rng, 5)
    T_cart = np.linalg.inv(T_UF) @ robot.fk_flange(q_cart) @ T_TOOL
    (tmp_path / "POSREG.VA").write_text(_posreg(cal, q_joint, q_cart, T_cart))
    (tmp_path / "prs.ls").write_text(_program(3, 4))
    frames = [
        "--uframe", "1=" + ",".join(f"{x:.9f}" for x in _numbers("fanuc-ls", T_UF)),
        "--utool", "1=" + ",".join(f"{x:.9f}" for x in _numbers("fanuc-ls", T_TOOL)),
    ]  # fmt: skip
    res = run_cli(
        "compensate", tmp_path / "prs.ls", "--model", model_file,
        "--out", tmp_path / "out.ls", "--registers", tmp_path / "POSREG.VA",
        "--json", *frames,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["ok"] == 7 and summary["unreachable"] == 0
    # Counted: 7 corrected; PR[19] uninitialised and PR[8], moved to in a user frame
    # taken from a register, left and named; PR[R[7]] left in the program.
    lines = (tmp_path / "prs.ls").read_text().splitlines()
    at = {k: next(i for i, ln in enumerate(lines, 1) if k in ln) for k in
          ("PR[19]", "PR[R[7]]", "PR[8]")}  # fmt: skip
    assert "9 position registers moved to: 7 corrected, 2 left" in res.stderr, (
        res.stderr
    )
    assert f"PR[19] (program line {at['PR[19]']}): not initialised in" in res.stderr
    assert f"PR[8] (program line {at['PR[8]']}): the program selects no" in res.stderr
    assert f"line {at['PR[R[7]]']} (PR[R[7]]): left as written" in res.stderr
    written = (tmp_path / "out_PR.ls").read_text()
    assert written.startswith("/PROG  OUT_PR") and "/MN" in written
    got = _assignments(written)
    assert sorted(got) == list(range(1, 8)) and all(len(v) == 6 for v in got.values())
    # Joint registers: the calibrated robot at the new joints takes the nominal flange
    # pose of the taught ones.
    for i, q in enumerate(q_joint, 1):
        q_new = np.radians([got[i][j] for j in range(1, 7)])
        F = calibrated_flange(cal, q_new[None])[0]
        err = np.linalg.norm(F[:3, 3] - robot.fk_flange(q)[:3, 3]) * 1e3
        assert err < 0.01, (i, err)
    # Cartesian registers: the nominal controller commanded to the new values puts the
    # calibrated robot's tool on the taught pose.
    for k, i in enumerate(range(4, 8)):  # PR[8] (q_cart[4]) is left
        T_new = _read_pose("fanuc-ls", [got[i][j] for j in range(1, 7)])
        q_c = _controller(robot, T_UF @ T_new @ np.linalg.inv(T_TOOL), q_cart[k])
        got_T = calibrated_flange(cal, q_c[None])[0] @ T_TOOL
        want = T_UF @ T_cart[k]
        assert np.linalg.norm(got_T[:3, 3] - want[:3, 3]) * 1e3 < 0.01
        moved = np.linalg.norm(T_new[:3, 3] - T_cart[k][:3, 3]) * 1e3
        assert moved > 0.1  # corrected, not copied
        assert Rotation.from_matrix(T_new[:3, :3]).magnitude() >= 0
    # The program itself is unchanged (its positions are all registers).
    assert (tmp_path / "out.ls").read_text() == (tmp_path / "prs.ls").read_text()


def test_issue_34_registers_reader_and_motions(tmp_path):
    va = tmp_path / "POSREG.VA"
    va.write_text(
        "[*POSREG*]$POSREG  Storage: CMOS  Access: RW  : ARRAY[2,4] OF Position Reg\n"
        "    [1,1] =   'Home'   Group: 1\n"
        "  J1 =     0.000 deg   J2 =   -60.000 deg   J3 =      .500 deg \n"
        "  J4 =     0.000 deg   J5 =    90.000 deg   J6 =     -.250 deg \n"
        "  EXT1:     0.000 mm  \n\n"
        "    [1,2] =   'Home2' Uninitialized\n"
        "    [1,3] =   'Pick' \n"
        "  Group: 1   Config: F U T, 0, 0, -1\n"
        "  X:  2066.881   Y: -1269.113   Z: -1122.291\n"
        "  W:  -179.786   P:     -.649   R:   -58.819\n"
        "    [2,3] =   'Rail' \n"
        "  Group: 2   Config: N, 0, 0, 0\n"
        "  X:  1.0   Y: 2.0   Z: 3.0\n"
        "  W:  0   P:  0   R:  0\n"
    )
    regs = read_position_registers(va)
    assert sorted(regs) == [1, 3]  # group 1 only, initialised only
    assert regs[1].joints == (0.0, -60.0, 0.5, 0.0, 90.0, -0.25)
    assert regs[3].cartesian == (
        2066.881,
        -1269.113,
        -1122.291,
        -179.786,
        -0.649,
        -58.819,
    )
    assert regs[3].config == "F U T, 0, 0, -1" and regs[3].comment == "Pick"
    text = (
        "/MN\n   1:  UFRAME_NUM=2 ;\n   2:L P[1] 100mm/sec FINE Offset,PR[3] ;\n"
        "   3:  !J PR[9] ;\n   4:L PR[GP1:3] 100mm/sec FINE ;\n   5:  UTOOL_NUM=4 ;\n"
        "   6:J PR[R[2]] 50% CNT100 ;\n"
    )
    got = [(m.index, m.line, m.uframe, m.utool) for m in register_motions(text)]
    assert got == [(3, 5, "2", None), (None, 7, "2", "4")]


@pytest.mark.parametrize(
    ("body", "needle"),
    [
        ("no registers here\n", "no $POSREG"),
        (
            "[*POSREG*]$POSREG : ARRAY[1,2] OF Position Reg\n    [1,1] =   'x' \n"
            "  Group: 1   Config: N U T, 0, 0, 0\n  X: 1 Y: 2\n",
            "line 2: PR[1] is neither a joint position",
        ),
        (
            "[*POSREG*]$POSREG : ARRAY[1,2] OF Position Reg\n    [1,1] =   'x' Group: 1\n"
            "  J1 =  ******** deg   J2 = 0.0 deg\n",
            "line 2: PR[1] J1 is not set",
        ),
    ],
)
def test_issue_34_malformed_registers_name_file_and_line(tmp_path, body, needle):
    va = tmp_path / "POSREG.VA"
    va.write_text(body)
    with pytest.raises(DataError, match=re.escape(needle)) as e:
        read_position_registers(va)
    assert str(e.value).startswith(str(va))


def test_issue_34_registers_for_other_formats_and_outputs_refused(
    model_file, run_cli, tmp_path
):
    va = tmp_path / "POSREG.VA"
    va.write_text("[*POSREG*]$POSREG : ARRAY[1,1] OF Position Reg\n")
    script = tmp_path / "a.script"
    script.write_text("def a():\n  movej([0,0,0,0,0,0])\nend\n")
    res = run_cli(
        "compensate", script, "--model", model_file, "--out", tmp_path / "b.script",
        "--registers", va,
    )  # fmt: skip
    assert res.returncode == 2 and "--registers" in res.stderr
    assert "FANUC" in res.stderr
    ls = tmp_path / "p.ls"
    ls.write_text(_program(1, 0))
    (tmp_path / "out_PR.ls").write_text("keep")
    res = run_cli(
        "compensate", ls, "--model", model_file, "--out", tmp_path / "out.ls",
        "--registers", va,
    )  # fmt: skip
    assert res.returncode != 0 and "out_PR.ls" in res.stderr and "--force" in res.stderr
    assert (tmp_path / "out_PR.ls").read_text() == "keep"
    assert not (tmp_path / "out.ls").exists()


def test_issue_34_a_wild_register_is_named_by_the_register(
    model_file, run_cli, tmp_path
):
    va = tmp_path / "POSREG.VA"
    va.write_text(
        "[*POSREG*]$POSREG  Storage: CMOS  Access: RW  : ARRAY[1,2] OF Position Reg\n"
        "    [1,1] =   'Home'   Group: 1\n"
        "  J1 = 1000000000.000 deg   J2 = 0.000 deg   J3 = 0.000 deg \n"
        "  J4 =     0.000 deg   J5 =   -30.000 deg   J6 =  0.000 deg \n"
    )
    ls = tmp_path / "p.ls"
    ls.write_text(_program(1, 0))
    res = run_cli(
        "compensate", ls, "--model", model_file, "--out", tmp_path / "o.ls",
        "--registers", va,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert f"{va}: PR[1]: J1 = 1e+09 deg is not a joint value" in res.stderr
    assert "registers.ls" not in res.stderr  # not the stand-in program's name
