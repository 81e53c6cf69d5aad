"""Issue 34, third round: FANUC moves with a position-register offset (``Offset,PR[k]``,
``Tool_Offset,PR[k]``, the bare options after ``OFFSET CONDITION`` / ``TOOL_OFFSET
CONDITION``) are corrected for, or checked at, the pose the robot goes to; RAPID
``RelTool`` with \\Rx, \\Ry and \\Rz together in ABB's order. The offset poses are
computed here with scipy's Rotation, and the corrected program is read by the stand-in
nominal controller of test_issue_34_cartesian."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.compensation._configs import encode_config
from kinecal.io._cartesian_programs import apply_offset, read_cartesian, remove_offset
from tests.compensation.test_issue_34_cartesian import (
    _NUM,
    T_TOOL,
    T_UF,
    _controller,
    _numbers,
    _read_pose,
    _targets,
    _taught,
)
from tests.compensation.test_issue_34_registers import _apply
from tests.compensation.test_issue_34_urscript_rapid import (
    _robtarget,
    rapid_frame_lines,
)

# Offset registers: X, Y, Z [mm], W, P, R [deg].
PR_VALUES = {
    5: [10.0, -5.0, 15.0, 2.0, -1.5, 3.0],  # Offset, with a rotation
    6: [3.0, -2.0, -30.0, 1.0, 0.5, 10.0],  # Tool_Offset: approach and twist
    7: [0.0, 0.0, 20.0, 0.0, 0.0, 0.0],  # 20 mm above a point moved to directly
}


def _M(k):
    """PR[k] as a pose, FANUC W, P, R about the fixed x, y, z axes (scipy 'xyz')."""
    v = PR_VALUES[k]
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("xyz", v[3:], degrees=True).as_matrix()
    T[:3, 3] = np.asarray(v[:3]) * 1e-3
    return T


# Per P[i] (i = 1..9): the motion lines, and how the robot's pose follows from P[i]
# ('U': user-frame offset M·P, 'T': tool-frame offset P·M, None: P itself).
MOVES = [
    (["J P[1] 100% FINE ;"], None),
    (["J P[2] 100% FINE Offset,PR[5] ;"], ("U", 5)),
    (["L P[3] 200mm/sec CNT50 Tool_Offset,PR[6:approach] ;"], ("T", 6)),
    (["L P[4] 200mm/sec FINE ;", "L P[4] 200mm/sec FINE Offset,PR[7] ;"], None),
    (["OFFSET CONDITION PR[5] ;", "L P[5] 100mm/sec FINE Offset ;"], ("U", 5)),
    (
        ["TOOL_OFFSET CONDITION PR[6] ;", "L P[6] 100mm/sec FINE Tool_Offset ;"],
        ("T", 6),
    ),
    (["L P[7] 100mm/sec FINE Offset,PR[8] ;"], "left"),  # PR[8] not given
    (["L P[8] 100mm/sec FINE Offset,PR[9] ;"], "left"),  # PR[9] holds joints
    (["L P[9] 100mm/sec FINE Offset,PR[R[2]] ;"], "left"),  # indirect
]


def _commanded(P, how):
    if how is None or how == "left":
        return P
    kind, k = how
    return _M(k) @ P if kind == "U" else P @ _M(k)


def _program(cal, q, T_goal):
    flags = encode_config(cal, "fanuc-ls", q)
    lines = ["UFRAME_NUM=1 ;", "UTOOL_NUM=1 ;"]
    for mv, _ in MOVES:
        lines += mv
    lines.append("L PR[10:place] 100mm/sec FINE Tool_Offset,PR[6] ;")
    mn = [
        f"{k + 1:4d}:{'' if ln[0] in 'JL' else '  '}{ln}" for k, ln in enumerate(lines)
    ]
    pos = []
    for i, (_, how) in enumerate(MOVES):
        P = T_goal[i]
        if how not in (None, "left"):  # the point whose offset pose is the goal
            kind, k = how
            P = np.linalg.inv(_M(k)) @ P if kind == "U" else P @ np.linalg.inv(_M(k))
        x, y, z, w, p, r = _numbers("fanuc-ls", P)
        f = flags[i]
        pos += [
            f"P[{i + 1}]{{", "   GP1:",
            f"\tUF : 1, UT : 1,\t\tCONFIG : '{f[0]} {f[1]} {f[2]}, {f[3]}, {f[4]}, {f[5]}',",
            f"\tX = {x:9.3f}  mm,\tY = {y:9.3f}  mm,\tZ = {z:9.3f}  mm,",
            f"\tW = {w:9.3f} deg,\tP = {p:9.3f} deg,\tR = {r:9.3f} deg", "};",
        ]  # fmt: skip
    return "\r\n".join(["/PROG  OFFS", "/ATTR", "/MN", *mn, "/POS", *pos, "/END", ""])


def _frames_yaml(cal, q10, T10):
    row = lambda v: ", ".join(f"{x:.6f}" for x in v)  # noqa: E731
    f = encode_config(cal, "fanuc-ls", q10[None])[0]
    cfg = f"{f[0]} {f[1]} {f[2]}, {f[3]}, {f[4]}, {f[5]}"
    doc = [
        "uframe:",
        f"  1: [{row(_numbers('fanuc-ls', T_UF))}]",
        "utool:",
        f"  1: [{row(_numbers('fanuc-ls', T_TOOL))}]",
        "posreg:",
    ]
    for k, v in PR_VALUES.items():
        doc.append(f"  {k}: {{config: 'N U T, 0, 0, 0', xyzwpr: [{row(v)}]}}")
    doc.append("  9: {joints: [0, 0, 0, 0, -90, 0]}")
    doc.append(f"  10: {{config: '{cfg}', xyzwpr: [{row(_numbers('fanuc-ls', T10))}]}}")
    return "\n".join(doc) + "\n"


def _written(text):
    keys = [rf"\b{k}\s*=\s*({_NUM})" for k in "XYZWPR"]
    recs = re.findall(r"P\[(\d+)\]\{(.*?)\};", text, re.S)
    return {
        int(n): _read_pose("fanuc-ls", [float(re.search(k, r).group(1)) for k in keys])
        for n, r in recs
    }


def test_issue_34_fanuc_offset_moves_reached_through_the_nominal_controller(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    q = _taught(np.random.default_rng(3434), 11)
    T_goal = _targets(cal, q)  # where the robot must go, in user frame 1
    # PR[10]: a register target moved to with Tool_Offset,PR[6].
    T10 = T_goal[10] @ np.linalg.inv(_M(6))
    src, out = tmp_path / "offs.ls", tmp_path / "corrected.ls"
    src.write_bytes(_program(cal, q[:10], T_goal).encode())
    (tmp_path / "f.yaml").write_text(_frames_yaml(cal, q[10], T10))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--frames", str(tmp_path / "f.yaml"), "--json", "--tol-mm", "0.005",
        "--report", str(tmp_path / "r.csv"),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # P[1..9], the second move to P[4] (with Offset,PR[7]) and PR[10]: every move counted.
    assert summary["n"] == 11, res.stderr
    for text in (
        "(P[7]): left as written: Offset,PR[8]: the offset register's value is in the "
        "controller",
        "(P[8]): left as written: Offset,PR[9]: the offset register holds joints",
        "(P[9]): left as written: Offset,PR[R[2]]: an indirect register index",
    ):
        assert text in res.stderr, res.stderr
    new = _written(out.read_text())
    errs = {}
    for i, (_, how) in enumerate(MOVES):
        if how == "left":
            assert np.allclose(new[i + 1], _written(src.read_text())[i + 1])
            continue
        F = T_UF @ _commanded(new[i + 1], how) @ np.linalg.inv(T_TOOL)
        q_ctrl = _controller(robot, F, q[i])
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        errs[i + 1] = np.linalg.norm(got[:3, 3] - (T_UF @ T_goal[i])[:3, 3]) * 1e3
        assert np.linalg.norm(new[i + 1][:3, 3] - T_goal[i][:3, 3]) * 1e3 > 0.1
    # The register target: its corrected value from the register program.
    regs = _apply((tmp_path / "CORRECTED_PR.ls").read_text(),
                  {10: _numbers("fanuc-ls", T10)})  # fmt: skip
    T10_new = _read_pose("fanuc-ls", regs[10])
    F = T_UF @ T10_new @ _M(6) @ np.linalg.inv(T_TOOL)
    got = calibrated_flange(cal, _controller(robot, F, q[10])[None])[0] @ T_TOOL
    errs[10] = np.linalg.norm(got[:3, 3] - (T_UF @ T_goal[10])[:3, 3]) * 1e3
    assert max(errs.values()) < 0.01, errs
    # P[4] with Offset,PR[7]: P[4] is corrected for its own move; 20 mm above, the
    # calibrated robot's error as the controller reads the corrected P[4], against
    # the taught P[4] shifted.
    want = T_UF @ _M(7) @ T_goal[3]
    F_new = T_UF @ _M(7) @ new[4] @ np.linalg.inv(T_TOOL)
    q_ctrl = _controller(robot, F_new, q[3])
    err = np.linalg.norm((calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL)[:3, 3]
                         - want[:3, 3]) * 1e3  # fmt: skip
    ok = err <= 0.005
    assert summary["ok"] == 7 + ok and summary["left"] == 3 + (not ok), res.stderr
    if not ok:
        m = re.search(r"\(P\[4\] Offset,PR\[7\]\): left as written: follows P\[4\]'s "
                      r"correction, (\S+) mm", res.stderr)  # fmt: skip
        assert m and abs(float(m.group(1)) - err) < 2e-4, (res.stderr, err)
    report = (tmp_path / "r.csv").read_text()
    assert "P[4] Offset;PR[7]; Cartesian" in report


def test_issue_34_reltool_rotations_in_abbs_order():
    """ABB's RelTool turns about the tool's x axis, then the new y, then the new z
    (scipy's intrinsic 'XYZ'), after the displacement in the tool frame."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec([0.3, -0.2, 0.5]).as_matrix()
    T[:3, 3] = [0.4, -0.1, 0.3]
    off = ("RelTool", 5.0, -4.0, -25.0, 12.0, -8.0, 30.0)
    M = np.eye(4)
    M[:3, :3] = Rotation.from_euler("XYZ", [12.0, -8.0, 30.0], degrees=True).as_matrix()
    M[:3, 3] = [0.005, -0.004, -0.025]
    np.testing.assert_allclose(apply_offset(T, off), T @ M, atol=1e-12)
    np.testing.assert_allclose(remove_offset(T @ M, off), T, atol=1e-12)
    # Not the fixed-axis order (the two differ by degrees here).
    Z = Rotation.from_euler("xyz", [12.0, -8.0, 30.0], degrees=True).as_matrix()
    assert Rotation.from_matrix(Z.T @ M[:3, :3]).magnitude() > np.radians(1.0)


@pytest.mark.parametrize("kind", ["Offset", "Tool_Offset"])
def test_issue_34_fanuc_offset_is_the_registers_pose(kind):
    """Offset: the register's pose applied in the user frame (M · P); Tool_Offset: in the
    tool frame (P · M); W, P, R about the fixed x, y, z axes."""
    P = np.eye(4)
    P[:3, :3] = Rotation.from_rotvec([-0.4, 0.1, 0.9]).as_matrix()
    P[:3, 3] = [0.5, 0.2, -0.1]
    M = _M(5)
    want = M @ P if kind == "Offset" else P @ M
    got = apply_offset(P, (kind, *PR_VALUES[5]))
    np.testing.assert_allclose(got, want, atol=1e-12)
    np.testing.assert_allclose(remove_offset(got, (kind, *PR_VALUES[5])), P, atol=1e-12)


def _reltool_M(d_mm, rxyz_deg):
    """RelTool's pose by ABB's words, with scipy: intrinsic rotations x, y', z''."""
    M = np.eye(4)
    M[:3, :3] = Rotation.from_euler("XYZ", rxyz_deg, degrees=True).as_matrix()
    M[:3, 3] = np.asarray(d_mm) * 1e-3
    return M


def test_issue_34_rapid_reltool_with_three_rotations_reached(
    tracker_twin, model_file, run_cli, tmp_path
):
    """A robtarget reached only through RelTool(p, dx, dy, dz \\Rx \\Ry \\Rz) is
    corrected for that pose: the stand-in controller, reading the corrected robtarget
    through scipy's RelTool, puts the calibrated robot on the taught pose."""
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    q = _taught(np.random.default_rng(3435), 2)
    flags = encode_config(cal, "rapid", q)
    T_goal = _targets(cal, q)
    rel = [([5, -4, -25], [12, -8, 30]), ([0, 10, 0], [-20, 15, -40])]
    base = [T_goal[i] @ np.linalg.inv(_reltool_M(*rel[i])) for i in range(2)]
    lines = [
        "MODULE Rel",
        *rapid_frame_lines(),
        *(_robtarget(f"p{i}", base[i], flags[i]) for i in range(2)),
        "PROC main()",
        "  MoveJ RelTool(p0, 5, -4, -25 \\Rx:=12 \\Ry:=-8 \\Rz:=30), v200, fine, "
        "tGrip\\WObj:=wTable;",
        "  MoveL RelTool(p1, 0, 10, 0 \\Rz:=-40 \\Rx:=-20 \\Ry:=15), v200, fine, "
        "tGrip\\WObj:=wTable;",
        "ENDPROC",
        "ENDMODULE",
        "",
    ]  # fmt: skip
    src, out = tmp_path / "r.mod", tmp_path / "c.mod"
    src.write_text("\n".join(lines))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out), "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["n"] == 2 and summary["ok"] == 2, res.stderr
    recs = re.findall(r"robtarget (p\d):=\[\[([^\]]*)\],\[([^\]]*)\]", out.read_text())
    new = {n: _read_pose("rapid", [float(x) for x in (a + "," + b).split(",")])
           for n, a, b in recs}  # fmt: skip
    for i in range(2):
        F = T_UF @ new[f"p{i}"] @ _reltool_M(*rel[i]) @ np.linalg.inv(T_TOOL)
        q_ctrl = _controller(robot, F, q[i])
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        err = np.linalg.norm(got[:3, 3] - (T_UF @ T_goal[i])[:3, 3]) * 1e3
        assert err < 0.01, (i, err)


_READ = """/PROG  EDGE
/MN
   1:  UFRAME_NUM=1 ;
   2:  UTOOL_NUM=1 ;
   3:  OFFSET CONDITION PR[5],UFRAME[2] ;
   4:L P[1] 100mm/sec FINE Offset ;
   5:L P[2] 100mm/sec FINE Tool_Offset ;
   6:C P[3]
    :  P[4] 100mm/sec FINE Offset,PR[6] ;
   7:L P[5] 100mm/sec FINE Offset,PR[7] ;
   8:J PR[20] 100% FINE Offset,PR[6] ;
/POS
{pos}/END
"""


def test_issue_34_fanuc_offset_cases_read():
    """A condition in another user frame, a bare Tool_Offset without its condition, a
    circular move's two points, an uninitialized register, a joint register target with
    an offset: each counted, with its reason where it is left."""
    from kinecal.io._fanuc_va import Register

    rec = (
        "P[{n}]{{\n   GP1:\n\tUF : 1, UT : 1,\t\tCONFIG : 'N U T, 0, 0, 0',\n"
        "\tX = 500.000  mm,\tY = 0.000  mm,\tZ = 300.000  mm,\n"
        "\tW = 180.000 deg,\tP = 0.000 deg,\tR = 0.000 deg\n}};\n"
    )
    text = _READ.format(pos="".join(rec.format(n=n) for n in range(1, 6)))
    regs = {
        5: Register(5, "", "cartesian", (1.0, 2, 3, 0, 0, 0), "N U T, 0, 0, 0", 0),
        6: Register(6, "", "cartesian", (0.0, 0, 20, 0, 0, 0), "N U T, 0, 0, 0", 0),
        7: Register(7, "", "uninitialized", (), "", 0),
        20: Register(20, "", "joint", (0.0, 0, 0, 0, -90, 0), "", 0),
    }
    pts = {p.name: p for p in read_cartesian(text, "fanuc-ls", regs)}
    assert set(pts) == {"PR[20]", "P[1]", "P[2]", "P[3]", "P[4]", "P[5]"}
    assert (
        "its condition's UFRAME[2] is not the target's frame 1" in pts["P[1]"].why_not
    )
    assert "no TOOL_OFFSET CONDITION before it" in pts["P[2]"].why_not
    for n in ("P[3]", "P[4]"):  # both points of the circular move take the offset
        assert pts[n].offset == ("Offset", 0.0, 0.0, 20.0, 0.0, 0.0, 0.0)
        assert pts[n].why_not == ""
    assert "uninitialized" in pts["P[5]"].why_not
    assert "a joint register moved to with an offset" in pts["PR[20]"].why_not
