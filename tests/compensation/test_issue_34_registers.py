"""Issue 34, second round: FANUC position registers (a controller's POSREG.VA or posreg:
in a YAML file) corrected into a register program OUT_PR.LS, frames from SYSFRAME.VA;
every register target counted. The corrected values are applied as the controller would
run the register program, read by the stand-in nominal controller of
test_issue_34_cartesian, and the calibrated robot must reach the taught pose."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.compensation._configs import encode_config
from tests.compensation.test_issue_34_cartesian import (
    T_TOOL,
    T_UF,
    _controller,
    _numbers,
    _read_pose,
    _targets,
    _taught,
)
from tests.helpers import unmarked


def _va_number(x: float) -> str:
    s = f"{x:9.3f}"
    return s.replace("0.", ".", 1) if abs(x) < 1 and s.strip()[0] in "0-" else s


def _posreg(cal, q, T_tg, q_joint):
    """A POSREG.VA: PR[1..n] Cartesian (as controllers print them: no leading zero),
    PR[20] joints, PR[21] uninitialized, a group-2 entry."""
    flags = encode_config(cal, "fanuc-ls", q)
    out = [
        "[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[2,100] OF Position Reg"
    ]
    for i, (T, f) in enumerate(zip(T_tg, flags)):
        x, y, z, w, p, r = (_va_number(v) for v in _numbers("fanuc-ls", T))
        out += [
            f"    [1,{i + 1}] =   'PICK{i}' ",
            f"  Group: 1   Config: {f[0]} {f[1]} {f[2]}, {f[3]}, {f[4]}, {f[5]}",
            f"  X: {x}   Y: {y}   Z: {z}",
            f"  W: {w}   P: {p}   R: {r}",
        ]  # fmt: skip
    j = [f"{v:9.3f}" for v in np.degrees(q_joint)]
    out += [
        "    [1,20] =   'HOME'   Group: 1",
        f"  J1 = {j[0]} deg   J2 = {j[1]} deg   J3 = {j[2]} deg ",
        f"  J4 = {j[3]} deg   J5 = {j[4]} deg   J6 = {j[5]} deg ",
        "",
        "    [1,21] =   '' Uninitialized",
        "    [2,1] =   'Rail' Uninitialized",
    ]
    return "\r\n".join([*out, ""])


def _sysframe():
    def block(name, T):
        x, y, z, w, p, r = (f"{v:9.3f}" for v in _numbers("fanuc-ls", T))
        return [
            f"[*SYSTEM*]${name}  Storage: CMOS  Access: RW  : ARRAY[1,9] OF POSITION",
            "    [1,1] = ",
            "  Group: 1   Config: N D B, 0, 0, 0",
            f"  X: {x}   Y: {y}   Z: {z}",
            f"  W: {w}   P: {p}   R: {r}",
            "    [1,2] = Uninitialized",
            "",
        ]

    return "\r\n".join([*block("MNUFRAME", T_UF), *block("MNUTOOL", T_TOOL), ""])


def _program(n):
    lines = ["UFRAME_NUM=1 ;", "UTOOL_NUM=1 ;", "J PR[20:HOME] 100% FINE ;"]
    lines += [f"L PR[{i + 1}:PICK{i}] 100mm/sec FINE ;" for i in range(n)]
    lines += ["J PR[21] 100% FINE ;", "J PR[R[3]] 100% FINE ;", "J PR[30] 100% FINE ;"]
    lines += ["L PR[1:PICK0] 50mm/sec CNT50 ;"]  # a second use, same frames
    mn = [f"{k + 1:4d}:  {ln}" for k, ln in enumerate(lines)]
    return "\r\n".join(["/PROG  PRS", "/ATTR", "/MN", *mn, "/POS", "/END", ""])


def _apply(text, regs):
    """The register program run on the controller: PR[n,j]=v element by element."""
    out = {n: list(v) for n, v in regs.items()}
    for n, j, v in re.findall(r"PR\[(\d+),(\d+)\]=(\S+) ;", text):
        out[int(n)][int(j) - 1] = float(v)
    return out


@pytest.mark.parametrize("source", ["va", "yaml"])
def test_issue_34_position_registers_corrected_through_the_nominal_controller(
    tracker_twin,
    model_file,
    run_cli,
    tmp_path,
    source,
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    q = _taught(np.random.default_rng(134), 6)
    q_home = _taught(np.random.default_rng(135), 1)[0]
    T_tg = _targets(cal, q)
    prog = tmp_path / "prs.ls"
    prog.write_bytes(_program(6).encode())
    if source == "va":
        (tmp_path / "POSREG.VA").write_bytes(_posreg(cal, q, T_tg, q_home).encode())
        (tmp_path / "SYSFRAME.VA").write_bytes(_sysframe().encode())
        frames = ["--frames", str(tmp_path / "SYSFRAME.VA"),
                  "--frames", str(tmp_path / "POSREG.VA")]  # fmt: skip
    else:
        flags = encode_config(cal, "fanuc-ls", q)
        row = lambda T: ", ".join(f"{v:.6f}" for v in _numbers("fanuc-ls", T))  # noqa: E731
        doc = [
            "uframe:",
            f"  1: [{row(T_UF)}]",
            "utool:",
            f"  1: [{row(T_TOOL)}]",
            "posreg:",
        ]
        for i, (T, f) in enumerate(zip(T_tg, flags)):
            v = ", ".join(f"{x:.3f}" for x in _numbers("fanuc-ls", T))
            cfg = f"{f[0]} {f[1]} {f[2]}, {f[3]}, {f[4]}, {f[5]}"
            doc.append(f"  {i + 1}: {{config: '{cfg}', xyzwpr: [{v}]}}")
        jv = ", ".join(f"{x:.3f}" for x in np.degrees(q_home))
        doc.append(f"  20: {{joints: [{jv}]}}")
        (tmp_path / "f.yaml").write_text("\n".join(doc) + "\n")
        frames = ["--frames", str(tmp_path / "f.yaml")]
    out = tmp_path / "corrected.ls"
    res = run_cli(
        "compensate", str(prog), "--model", str(model_file), "--out", str(out),
        "--json", *frames,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # PR[20], PR[1..6] corrected; PR[21] (uninitialized / not given), PR[R[3]], PR[30]
    # left, each with its reason.
    assert summary["n"] == 10 and summary["ok"] == 7 and summary["left"] == 3
    assert (
        "10 Cartesian targets: 7 corrected, 3 left as written, 0 unreachable"
        in res.stderr
    )
    assert "(PR[R[3]]): left as written: an indirect register index" in res.stderr
    assert "(PR[30]): left as written: a position register: its value is" in res.stderr
    # the program itself is unchanged (but for the comment that marks it compensated)
    assert unmarked(out.read_text(), prog.read_text()) == prog.read_text()
    reg_prog = (tmp_path / "CORRECTED_PR.ls").read_bytes().decode()
    assert reg_prog.startswith("/PROG  CORRECTED_PR\r\n") and reg_prog.endswith(
        "/END\r\n"
    )
    assert "DEFAULT_GROUP\t= *,*,*,*,*;" in reg_prog
    old = {i + 1: _numbers("fanuc-ls", T) for i, T in enumerate(T_tg)}
    old[20] = list(np.degrees(q_home))
    new = _apply(reg_prog, old)
    errs = []
    for i in range(6):
        T_new = _read_pose("fanuc-ls", new[i + 1])
        F = T_UF @ T_new @ np.linalg.inv(T_TOOL)
        q_ctrl = _controller(robot, F, q[i])
        np.testing.assert_allclose(q_ctrl, q[i], atol=np.radians(2.0))
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        errs.append(np.linalg.norm(got[:3, 3] - (T_UF @ T_tg[i])[:3, 3]) * 1e3)
        assert np.linalg.norm(T_new[:3, 3] - T_tg[i][:3, 3]) * 1e3 > 0.1  # moved
    # The joint register: the calibrated robot at the corrected joints takes the
    # nominal robot's flange pose at the taught ones.
    q_new = np.radians(new[20])
    got = calibrated_flange(cal, q_new[None])[0]
    errs.append(
        np.linalg.norm(got[:3, 3] - robot.fk_flange(q_home[None])[0][:3, 3]) * 1e3
    )
    assert max(errs) < 0.01, errs


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,3] OF Position Reg\n"
         "    [1,1] =   'A' \n  Group: 1   Config: N U T, 0, 0, 0\n"
         "  X:   1.000   Y:   2.000   Z:   3.000\n  W:   0.000   P:   0.000\n",
         r"POSREG.VA: line 5: expected 'R: <number>'"),
        ("[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,3] OF Position Reg\n"
         "    [1,1] =   'A'   Group: 1\n  J1 =  ******** deg\n",
         r"POSREG.VA: line 3: J1 is '\*+' \(not printable"),
        ("[*POSREG*]$POSREG  Storage: SHADOW  Access: RW  : ARRAY[1,3] OF Position Reg\n"
         "    [1,1] =   'A' \n  something else\n",
         r"POSREG.VA: line 2: \[1,1\]: expected 'Group: g\s+Config"),
        ("[*NUMREG*]$NUMREG  Storage: SHADOW  Access: RW  : ARRAY[2] OF Numeric Reg\n",
         r"POSREG.VA: no '\[\*POSREG\*\]\$POSREG' variable"),
    ],
)  # fmt: skip
def test_issue_34_malformed_register_files_name_file_and_line(
    tracker_twin,
    model_file,
    run_cli,
    tmp_path,
    text,
    message,
):
    prog = tmp_path / "prs.ls"
    prog.write_bytes(_program(1).encode())
    va = tmp_path / "POSREG.VA"
    va.write_text(text)
    if "NUMREG" in text:
        va = va.rename(tmp_path / "x.va")
        message = message.replace("POSREG.VA", "x.va")
        va.write_text(text.replace("NUMREG", "MNUFRAME").replace("$MNUFRAME ", "$X "))
        message = r"x.va: no '\$MNUFRAME' or '\$MNUTOOL' variable"
    _refused(run_cli, prog, model_file, va, message)


def _refused(run_cli, prog, model_file, frames, message):
    """compensate PROG --frames FRAMES fails with ``message``, writing nothing."""
    out = prog.parent / "o.ls"
    res = run_cli(
        "compensate", str(prog), "--model", str(model_file), "--out", str(out),
        "--frames", str(frames),
    )  # fmt: skip
    assert res.returncode != 0 and re.search(message, res.stderr), res.stderr
    assert "Traceback" not in res.stderr and not out.exists()


@pytest.mark.parametrize(
    ("yaml_text", "message"),
    [
        ("posreg:\n  1: {xyzwpr: [1, 2, 3]}\n", r"f.yaml: posreg 1: expected"),
        ("posreg:\n  0: {joints: [1, 2, 3, 4, 5, 6]}\n", r"f.yaml: posreg 0: expected"),
    ],
)
def test_issue_34_bad_posreg_yaml(
    tracker_twin,
    model_file,
    run_cli,
    tmp_path,
    yaml_text,
    message,
):
    prog = tmp_path / "prs.ls"
    prog.write_bytes(_program(1).encode())
    (tmp_path / "f.yaml").write_text(yaml_text)
    _refused(run_cli, prog, model_file, tmp_path / "f.yaml", message)


def test_issue_34_register_program_is_an_output(
    tracker_twin, model_file, run_cli, tmp_path
):
    """OUT_PR.LS: refused when it exists (before any work) unless --force, and never
    written over an input."""
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(136), 1)
    prog = tmp_path / "prs.ls"
    prog.write_bytes(_program(1).encode())
    va = tmp_path / "POSREG.VA"
    va.write_bytes(_posreg(cal, q, _targets(cal, q), q[0]).encode())
    (tmp_path / "SYSFRAME.VA").write_bytes(_sysframe().encode())
    pr = tmp_path / "C_PR.ls"
    pr.write_text("old")
    args = ["compensate", str(prog), "--model", str(model_file), "--out",
            str(tmp_path / "c.ls"), "--frames", str(tmp_path / "SYSFRAME.VA"),
            "--frames", str(va)]  # fmt: skip
    res = run_cli(*args)
    assert res.returncode != 0 and "C_PR.ls: exists; use --force" in res.stderr
    assert pr.read_text() == "old" and not (tmp_path / "c.ls").exists()
    res = run_cli(*args, "--force")
    assert res.returncode == 0, res.stderr
    assert pr.read_text().startswith("/PROG  C_PR")
    # The register program's path is an input: refused even with --force.
    va.rename(pr)
    res = run_cli(*args[:-1], str(pr), "--force")
    assert res.returncode != 0 and "C_PR.ls" in res.stderr, res.stderr
    assert pr.read_bytes().startswith(b"[*POSREG*]")


def test_issue_34_va_elements_as_controllers_print_them():
    """Config on the element line, numbers without a leading zero, EXT lines, other
    groups and uninitialized elements; SYSFRAME.VA frames by number."""
    from kinecal.io._fanuc_va import read_posreg, read_va_frames

    text = (
        "[*POSREG*]$POSREG  Storage: CMOS  Access: RW  : ARRAY[2,8] OF Position Reg\n"
        "    [1,6] =   'Maint'   Group: 1   Config: F U T, 0, 0, 1\n"
        "  X:  2066.881   Y: -1269.113   Z: -1122.291\n"
        "  W:  -179.786   P:     -.649   R:   -58.819\n"
        "  EXT1:    40.492 mm  \n"
        "    [1,7] =   '' Uninitialized\n"
        "    [2,7] =   'Turn'   Group: 2\n  J1 =    45.000 deg \n"
    )
    regs = read_posreg("POSREG.VA", text)
    assert sorted(regs) == [6, 7]
    assert regs[6].kind == "cartesian" and regs[6].config == "F U T, 0, 0, 1"
    assert regs[6].values == (2066.881, -1269.113, -1122.291, -179.786, -0.649, -58.819)
    assert regs[6].line == 2 and regs[7].kind == "uninitialized"
    uf, ut = read_va_frames("SYSFRAME.VA", _sysframe())
    assert sorted(uf) == ["1"] and sorted(ut) == ["1"]
    np.testing.assert_allclose(uf["1"], _numbers("fanuc-ls", T_UF), atol=6e-4)
