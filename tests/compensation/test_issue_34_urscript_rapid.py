"""Issue 34, second round: URScript targets relative to features (``pose_trans(Plane_1,
...)``) and pose variables assigned anywhere (``name = p[...]``, ``global``, ``local``);
RAPID moves to ``Offs(p10, ...)`` / ``RelTool(p10, ...)``. Every target counted; the
corrected ones reached through the stand-in nominal controller of
test_issue_34_cartesian within 0.01 mm."""

from __future__ import annotations

import json
import re

import numpy as np
from scipy.spatial.transform import Rotation

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.compensation._configs import encode_config
from tests.compensation.test_issue_34_cartesian import (
    T_TOOL,
    T_UF,
    _controller,
    _numbers,
    _read_pose,
    _taught,
)

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _ur(T):
    return "p[" + ", ".join(f"{x:.9f}" for x in _numbers("urscript", T)) + "]"


def _near(rng, q0, n):
    """Taught joints within 8 deg of q0 (one IK branch from the movej before)."""
    return q0 + np.radians(rng.uniform(-8, 8, (n, 6)))


def test_issue_34_urscript_features_and_pose_variables(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    rng = np.random.default_rng(341)
    q0 = _taught(rng, 1)[0]
    q = _near(rng, q0, 5)
    F = robot.fk_flange(q)
    T_base = F @ T_TOOL  # tool poses in the base frame
    T_feat = np.linalg.inv(T_UF) @ T_base  # ... in the feature Plane_1 (= T_UF)
    lines = [
        "def prog():",
        f"  set_tcp({_ur(T_TOOL)})",
        f"  global Plane_1={_ur(T_UF)}",
        f"  movej([{', '.join(f'{v:.6f}' for v in q0)}], a=1.4, v=1.05)",
        f"  global Waypoint_1_p={_ur(T_base[0])}",  # 5: base frame, Polyscope
        "  movel(Waypoint_1_p, a=1.2, v=0.25)",
        f"  Approach = {_ur(T_feat[1])}",  # 7: feature-relative variable
        "  movel(pose_trans(Plane_1, Approach), a=1.2, v=0.25)",
        f"  local Pick = {_ur(T_feat[2])}",  # 9: local, through get_inverse_kin
        "  movej(get_inverse_kin(pose_trans(Plane_1, Pick)), a=1.4, v=1.05)",
        f"  movel(pose_trans(Plane_1, {_ur(T_feat[3])}), a=1.2, v=0.25)",  # 11: inline
        f"  movel(pose_trans(Table_2, {_ur(T_feat[4])}), a=1.2, v=0.25)",  # 12: unknown
        f"  Both = {_ur(T_base[4])}",  # 13: also in an expression
        "  movel(Both, a=1.2, v=0.25)",
        "  movel(pose_add(Both, p[0, 0, 0.05, 0, 0, 0]), a=1.2, v=0.25)",
        f"  Lifted = {_ur(T_base[4])}",  # 16: reassigned from an expression
        "  Lifted = get_actual_tcp_pose()",
        "  movel(Lifted, a=1.2, v=0.25)",
        "  offset = p[0, 0, 0.1, 0, 0, 0]",  # no move goes to it: not a target
        "end",
    ]
    src, out = tmp_path / "f.script", tmp_path / "c.script"
    src.write_text("\n".join([*lines, ""]))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out), "--json"
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # 1 joint target + 7 Cartesian: Waypoint_1_p, Approach, Pick, inline, Table_2,
    # Both, Lifted (offset is no target).
    # the computed move (pose_add(Both, ..)) is counted too, and left
    assert summary["n"] == 9 and summary["ok"] == 5 and summary["left"] == 4, res.stderr
    assert "8 Cartesian targets: 4 corrected, 4 left as written" in res.stderr
    assert "a computed target (pose_add(Both" in res.stderr
    assert (
        "line 12 (movel): left as written: feature Table_2: its pose is not"
        in res.stderr
    )
    assert (
        "line 13 (Both): left as written: a move uses it in an expression (line 15)"
        in res.stderr
    )
    assert (
        "line 16 (Lifted): left as written: it is also assigned from an expression"
        in res.stderr
    )
    text = out.read_text().splitlines()
    for k, (ln, T_uf) in enumerate([(5, np.eye(4)), (7, T_UF), (9, T_UF), (11, T_UF)]):
        vals = [
            float(v)
            for v in re.search(r"p\[([^\]]*)\]", text[ln - 1]).group(1).split(",")
        ]
        T_new = _read_pose("urscript", vals)
        q_ctrl = _controller(robot, T_uf @ T_new @ np.linalg.inv(T_TOOL), q[k])
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        assert np.linalg.norm(got[:3, 3] - T_base[k][:3, 3]) * 1e3 < 0.01, k
        assert (
            np.linalg.norm(T_new[:3, 3] - (np.linalg.inv(T_uf) @ T_base[k])[:3, 3])
            > 1e-4
        )
    for ln in (12, 13, 16, 19):
        assert text[ln - 1] == lines[ln - 1]
    # The feature given on the command line: Table_2 is corrected too.
    table = "Table_2=" + _ur(T_UF)[2:-1].replace(" ", "")
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out",
        str(tmp_path / "d.script"), "--json", "--uframe", table,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout.strip().splitlines()[-1])["ok"] == 6


def _rapid_numbers(T):
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    return [*(T[:3, 3] * 1e3), w, x, y, z]


def _offs(T, d_mm):
    out = T.copy()
    out[:3, 3] += np.asarray(d_mm) * 1e-3
    return out


def _reltool(T, d_mm, rz_deg):
    M = np.eye(4)
    M[:3, :3] = Rotation.from_euler("z", rz_deg, degrees=True).as_matrix()
    M[:3, 3] = np.asarray(d_mm) * 1e-3
    return T @ M


def rapid_frame_lines():
    """The tooldata tGrip (T_TOOL) and wobjdata wTable (T_UF) declarations."""
    tool, uf = _rapid_numbers(T_TOOL), _rapid_numbers(T_UF)

    def pose(v):
        return (
            "[[" + ",".join(f"{x:.9f}" for x in v[:3]) + "],["
            + ",".join(f"{x:.9f}" for x in v[3:]) + "]]"
        )  # fmt: skip

    return [
        f"PERS tooldata tGrip:=[TRUE,{pose(tool)},[1,[0,0,1],[1,0,0,0],0,0,0]];",
        f'PERS wobjdata wTable:=[FALSE,TRUE,"",{pose(uf)},[[0,0,0],[1,0,0,0]]];',
    ]


def _robtarget(name, T, flags):
    v = _rapid_numbers(T)
    return (
        f"CONST robtarget {name}:=[[{v[0]:.4f},{v[1]:.4f},{v[2]:.4f}],"
        f"[{v[3]:.9f},{v[4]:.9f},{v[5]:.9f},{v[6]:.9f}],"
        f"[{flags[0]},{flags[1]},{flags[2]},{flags[3]}],"
        "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];"
    )


def test_issue_34_rapid_offs_and_reltool(tracker_twin, model_file, run_cli, tmp_path):
    """A robtarget reached only through Offs/RelTool is corrected for that pose; one
    reached directly and through Offs is corrected for itself and the offset move is
    checked and counted; offsets that are not numbers leave the robtarget."""
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    q = _taught(np.random.default_rng(342), 5)
    flags = encode_config(cal, "rapid", q)
    T_obj = np.linalg.inv(T_UF) @ robot.fk_flange(q) @ T_TOOL  # where the robot goes
    base = [
        T_obj[0],  # p0: MoveL p0
        T_obj[1],  # p1: MoveL p1 and MoveL Offs(p1, 0, 0, 20)
        _offs(T_obj[2], [0, 0, -30]),  # p2: only Offs(p2, 0, 0, 30)
        None,  # p3: set below
        T_obj[4],  # p4: Offs with a variable
    ]
    M = np.eye(4)
    M[:3, :3] = Rotation.from_euler("z", 30, degrees=True).as_matrix()
    M[:3, 3] = [0, 0, -0.025]
    base[3] = T_obj[3] @ np.linalg.inv(M)  # p3: only RelTool(p3, 0, 0, -25 \Rz:=30)
    lines = [
        "MODULE Offsets",
        *rapid_frame_lines(),
        *(_robtarget(f"p{i}", base[i], flags[i]) for i in range(5)),
        "PROC main()",
        "  MoveL p0, v200, fine, tGrip\\WObj:=wTable;",
        "  MoveL Offs(p1, 0, 0, 20), v200, z10, tGrip\\WObj:=wTable;",
        "  MoveL p1, v200, fine, tGrip\\WObj:=wTable;",
        "  MoveL Offs(p2, 0, 0, 30), v200, fine, tGrip\\WObj:=wTable;",
        "  MoveJ RelTool(p3, 0, 0, -25 \\Rz:=30), v200, fine, tGrip\\WObj:=wTable;",
        "  MoveL Offs(p4, 0, 0, dz), v200, fine, tGrip\\WObj:=wTable;",
        "ENDPROC",
        "ENDMODULE",
        "",
    ]  # fmt: skip
    src, out = tmp_path / "o.mod", tmp_path / "c.mod"
    src.write_text("\n".join(lines))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out), "--json",
        "--tol-mm", "0.005",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["n"] == 6, res.stderr  # p0..p4 and Offs(p1, ..)
    assert (
        "line 8 (p4): left as written: a move uses it in an expression or with "
        "offsets that are not numbers (line 15)" in res.stderr
    )
    recs = re.findall(r"robtarget (p\d):=\[\[([^\]]*)\],\[([^\]]*)\]", out.read_text())
    new = {n: _read_pose("rapid", [float(x) for x in (a + "," + b).split(",")])
           for n, a, b in recs}  # fmt: skip

    def reach(T_new_obj, k):
        F = T_UF @ T_new_obj @ np.linalg.inv(T_TOOL)
        q_ctrl = _controller(robot, F, q[k])
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        return np.linalg.norm(got[:3, 3] - (T_UF @ T_obj[k])[:3, 3]) * 1e3

    assert reach(new["p0"], 0) < 0.01
    assert reach(new["p1"], 1) < 0.01
    assert reach(_offs(new["p2"], [0, 0, 30]), 2) < 0.01
    assert reach(new["p3"] @ M, 3) < 0.01
    assert np.linalg.norm(new["p2"][:3, 3] - base[2][:3, 3]) * 1e3 > 0.1  # moved
    # Offs(p1, 0, 0, 20) follows p1: the controller's pose there, against the taught
    # Offs of the taught p1.
    want = T_UF @ _offs(T_obj[1], [0, 0, 20])
    F = want @ np.linalg.inv(T_TOOL)
    F_new = T_UF @ _offs(new["p1"], [0, 0, 20]) @ np.linalg.inv(T_TOOL)
    q_ctrl = _controller(robot, F_new, _controller(robot, F, q[1]))
    err = (
        np.linalg.norm(
            (calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL)[:3, 3] - want[:3, 3]
        )
        * 1e3
    )
    follow_ok = err <= 0.005
    assert summary["ok"] == 4 + follow_ok and summary["left"] == 2 - follow_ok
    if not follow_ok:
        m = re.search(r"Offs\(p1; 0; 0; 20\)\): left as written: follows p1's "
                      r"correction, (\S+) mm", res.stderr)  # fmt: skip
        assert m and abs(float(m.group(1)) - err) < 2e-4, (res.stderr, err)
    q0 = _controller(robot, F, q[1])  # uncorrected: the taught Offs as written
    err0 = (
        np.linalg.norm(
            (calibrated_flange(cal, q0[None])[0] @ T_TOOL)[:3, 3] - want[:3, 3]
        )
        * 1e3
    )
    assert err < 0.5 * err0, (err, err0)
