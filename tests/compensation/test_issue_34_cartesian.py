"""Issue 34, items 2 and 3: Cartesian program targets and singular poses, on the tracker
twin of issue 23 (the paper's LR Mate, calibrated with the full model).

The programs are written offline on the nominal model: a target is the tool pose the
nominal robot has at taught joints, in a user frame, with the configuration flags of those
joints. A stand-in controller reads the corrected program independently of kinecal's
solver (scipy least squares on the robot's nominal forward kinematics, started at the
taught joints; the flags checked), and the calibrated robot must then put the tool on the
taught pose.
"""

from __future__ import annotations

import dataclasses
import json
import re

import numpy as np
import pytest
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from kinecal.compensation._cartesian import calibrated_flange
from kinecal.compensation._configs import encode_config
from kinecal.io import save_model
from tests.compensation.conftest import box_poses

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _pose(xyz_m, rotvec) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = xyz_m
    return T


T_UF = _pose([0.35, -0.12, 0.08], [0.02, -0.03, 0.4])  # a user frame on the table
T_TOOL = _pose([0.01, 0.0, 0.12], [0.0, 0.25, 0.0])  # a tilted tool, 120 mm out


@pytest.fixture(scope="module")
def model_file(tracker_twin, tmp_path_factory):
    return save_model(
        tmp_path_factory.mktemp("p34") / "model.yaml", tracker_twin.calibrated
    )


def _taught(rng, n):
    """Taught joints away from the wrist singularity, J4/J6 inside one turn."""
    q = box_poses(rng, n)
    q[:, 4] = np.sign(rng.uniform(-1, 1, n)) * np.radians(rng.uniform(15, 100, n))
    q[:, 2] = np.clip(q[:, 2], -1.0, 0.3)
    return q


def _targets(cal, q, T_uf=T_UF, T_tool=T_TOOL):
    """Tool poses in the user frame the nominal robot has at ``q``."""
    return np.linalg.inv(T_uf) @ cal.model.robot.fk_flange(q) @ T_tool


def _numbers(fmt, T):
    R = Rotation.from_matrix(T[:3, :3])
    if fmt == "fanuc-ls":
        return [*(T[:3, 3] * 1e3), *R.as_euler("xyz", degrees=True)]
    if fmt == "krl":
        return [*(T[:3, 3] * 1e3), *R.as_euler("ZYX", degrees=True)]
    if fmt == "rapid":
        x, y, z, w = R.as_quat()
        return [*(T[:3, 3] * 1e3), w, x, y, z]
    return [*T[:3, 3], *R.as_rotvec()]


def _read_pose(fmt, v):
    v = np.asarray(v, float)
    T = np.eye(4)
    if fmt == "fanuc-ls":
        T[:3, :3] = Rotation.from_euler("xyz", v[3:6], degrees=True).as_matrix()
    elif fmt == "krl":
        T[:3, :3] = Rotation.from_euler("ZYX", v[3:6], degrees=True).as_matrix()
    elif fmt == "rapid":
        T[:3, :3] = Rotation.from_quat([*v[4:7], v[3]]).as_matrix()
    else:
        T[:3, :3] = Rotation.from_rotvec(v[3:6]).as_matrix()
        T[:3, 3] = v[:3]
        return T
    T[:3, 3] = v[:3] * 1e-3
    return T


def _fanuc(cal, q, T_tg):
    flags = encode_config(cal, "fanuc-ls", q)
    out = ["/PROG  CART", "/MN", "   1:L PR[5:home] 100mm/sec FINE    ;", "/POS"]
    for i, (T, f) in enumerate(zip(T_tg, flags)):
        x, y, z, w, p, r = _numbers("fanuc-ls", T)
        uf = 3 if i == len(T_tg) - 1 else 1  # the last one names a frame not given
        out += [
            f"P[{i + 1}]{{", "   GP1:",
            f"\tUF : {uf}, UT : 1,\t\tCONFIG : '{f[0]} {f[1]} {f[2]}, {f[3]}, {f[4]}, {f[5]}',",
            f"\tX = {x:9.3f}  mm,\tY = {y:9.3f}  mm,\tZ = {z:9.3f}  mm,",
            f"\tW = {w:9.3f} deg,\tP = {p:9.3f} deg,\tR = {r:9.3f} deg", "};",
        ]  # fmt: skip
    return "\r\n".join([*out, "/END", ""])


def _krl(cal, q, T_tg):
    flags = encode_config(cal, "krl", q)
    out = ["DEFDAT CART"]
    for i, (T, (s, t)) in enumerate(zip(T_tg, flags)):
        v = _numbers("krl", T)
        body = ",".join(f"{k} {x:.5f}" for k, x in zip("XYZABC", v))
        out.append(f"DECL E6POS XP{i + 1}={{{body},S {s},T {t},E1 0.0,E2 0.0}}")
        out.append(f"DECL FDAT FP{i + 1}={{TOOL_NO 2,BASE_NO 1,IPO_FRAME #BASE}}")
    return "\n".join([*out, "ENDDAT", ""])


def _rapid(cal, q, T_tg):
    flags = encode_config(cal, "rapid", q)
    tool = ",".join(f"{x:.9f}" for x in _numbers("rapid", T_TOOL)[:3])
    tq = ",".join(f"{x:.9f}" for x in _numbers("rapid", T_TOOL)[3:])
    uf = _numbers("rapid", T_UF)
    out = [
        "MODULE Cart",
        f"PERS tooldata tGrip:=[TRUE,[[{tool}],[{tq}]],[1,[0,0,1],[1,0,0,0],0,0,0]];",
        "PERS wobjdata wTable:=[FALSE,TRUE,\"\",[[" + ",".join(f"{x:.9f}" for x in uf[:3])
        + "],[" + ",".join(f"{x:.9f}" for x in uf[3:]) + "]],[[0,0,0],[1,0,0,0]]];",
    ]  # fmt: skip
    for i, (T, f) in enumerate(zip(T_tg, flags)):
        v = _numbers("rapid", T)
        out.append(
            f"CONST robtarget p{i}:=[[{v[0]:.4f},{v[1]:.4f},{v[2]:.4f}],"
            f"[{v[3]:.9f},{v[4]:.9f},{v[5]:.9f},{v[6]:.9f}],[{f[0]},{f[1]},{f[2]},{f[3]}],"
            "[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];"
        )
    out += ["PROC main()"]
    out += [f"  MoveL p{i}, v200, fine, tGrip\\WObj:=wTable;" for i in range(len(T_tg))]
    return "\n".join([*out, "ENDPROC", "ENDMODULE", ""])


def _urscript(cal, q, T_tg):
    tcp = ", ".join(f"{x:.9f}" for x in _numbers("urscript", T_TOOL))
    out = ["def cart():", f"  set_tcp(p[{tcp}])"]
    for i, (T, qq) in enumerate(zip(T_tg, q)):
        v = ", ".join(f"{x:.9f}" for x in _numbers("urscript", T))
        out.append(f"  global Waypoint_{i + 1}_p=p[{v}]")
        out.append(f"  global Waypoint_{i + 1}_q=[{', '.join(f'{x:.6f}' for x in qq)}]")
        out.append(f"  movel(Waypoint_{i + 1}_p, a=1.2, v=0.25)")
    return "\n".join([*out, "end", ""])


WRITERS = {"fanuc-ls": (_fanuc, ".ls"), "krl": (_krl, ".dat"),
           "rapid": (_rapid, ".mod"), "urscript": (_urscript, ".script")}  # fmt: skip
FRAME_ARGS = {
    "fanuc-ls": lambda: [
        "--uframe", "1=" + ",".join(f"{x:.9f}" for x in _numbers("fanuc-ls", T_UF)),
        "--utool", "1=" + ",".join(f"{x:.9f}" for x in _numbers("fanuc-ls", T_TOOL)),
    ],
    "krl": lambda: [
        "--uframe", "1=" + ",".join(f"{x:.9f}" for x in _numbers("krl", T_UF)),
        "--utool", "2=" + ",".join(f"{x:.9f}" for x in _numbers("krl", T_TOOL)),
    ],
    "rapid": lambda: [],  # tooldata and wobjdata in the module
    "urscript": lambda: [],  # set_tcp in the script, poses in the base frame
}  # fmt: skip


def _written_targets(fmt, text):
    """(values, flags) of every Cartesian target of a written program, read with regular
    expressions of this test (not kinecal's reader)."""
    if fmt == "fanuc-ls":
        keys = [rf"\b{k}\s*=\s*({_NUM})" for k in "XYZWPR"]
        recs = re.findall(r"P\[\d+\]\{(.*?)\};", text, re.S)
        vals = [[float(re.search(k, r).group(1)) for k in keys] for r in recs]
        flags = [re.search(r"CONFIG : '([^']*)'", r).group(1) for r in recs]
    elif fmt == "krl":
        recs = re.findall(r"E6POS \w+=\{([^}]*)\}", text)
        vals = [
            [float(re.search(rf"\b{k} ({_NUM})", r).group(1)) for k in "XYZABC"]
            for r in recs
        ]
        flags = [re.search(r"S \d+,T \d+", r).group(0) for r in recs]
    elif fmt == "rapid":
        recs = re.findall(
            r"robtarget \w+:=\[\[([^\]]*)\],\[([^\]]*)\],\[([^\]]*)\]", text
        )
        vals = [[float(x) for x in (a + "," + b).split(",")] for a, b, _ in recs]
        flags = [c for _, _, c in recs]
    else:
        recs = re.findall(r"_p=p\[([^\]]*)\]", text)
        vals = [[float(x) for x in r.split(",")] for r in recs]
        flags = [None] * len(recs)
    return vals, flags


def _controller(robot, F_want, q_start):
    """A stand-in controller: the nominal joints of flange pose F (least squares on the
    robot's nominal FK from the taught joints)."""

    def res(q):
        T = robot.fk_flange(q)
        dR = Rotation.from_matrix(F_want[:3, :3].T @ T[:3, :3]).as_rotvec()
        return np.concatenate([T[:3, 3] - F_want[:3, 3], 0.5 * dR])

    return least_squares(res, q_start, xtol=1e-15, ftol=1e-15, gtol=1e-15).x


@pytest.mark.parametrize("fmt", ["fanuc-ls", "krl", "rapid", "urscript"])
def test_issue_34_cartesian_targets_reached_through_the_nominal_controller(
    tracker_twin, model_file, run_cli, tmp_path, fmt
):
    cal = tracker_twin.calibrated
    robot = cal.model.robot
    rng = np.random.default_rng(34)
    q = _taught(rng, 10)
    writer, ext = WRITERS[fmt]
    T_uf = np.eye(4) if fmt == "urscript" else T_UF
    T_tg = _targets(cal, q, T_uf=T_uf)
    src, out = tmp_path / f"cart{ext}", tmp_path / f"corrected{ext}"
    src.write_bytes(writer(cal, q, T_tg).encode())
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--report", str(tmp_path / "r.csv"), "--json", *FRAME_ARGS[fmt](),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # FANUC: the last target names UF 3, not given, and PR[5] is the controller's.
    n_left, n = (2, 11) if fmt == "fanuc-ls" else (0, 10)
    n_ok = n - n_left
    assert summary["n"] == n and summary["left"] == n_left
    assert summary["ok"] == n_ok and summary["unreachable"] == 0
    assert f"{n} Cartesian targets: {n_ok} corrected, {n_left} left" in res.stderr
    if n_left:
        assert "user frame 3 not given (--uframe 3=" in res.stderr
        assert "line 3 (PR[5:home]): left as written: a position register" in res.stderr
    text = out.read_text()
    vals, flags = _written_targets(fmt, text)
    _, flags0 = _written_targets(fmt, src.read_text())
    assert flags == flags0 and len(vals) == 10  # the configuration kept
    errs, moved = [], []
    for i in range(n_ok):
        T_new = _read_pose(fmt, vals[i])
        F = T_uf @ T_new @ np.linalg.inv(T_TOOL)
        q_ctrl = _controller(robot, F, q[i])
        np.testing.assert_allclose(q_ctrl, q[i], atol=np.radians(2.0))  # its branch
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        want = T_uf @ T_tg[i]
        errs.append(np.linalg.norm(got[:3, 3] - want[:3, 3]) * 1e3)
        moved.append(np.linalg.norm(T_new[:3, 3] - T_tg[i][:3, 3]) * 1e3)
    assert max(errs) < 0.01, errs
    assert min(moved) > 0.1  # the targets did move (the calibration is ~1-3 mm off)
    # Uncorrected, the nominal controller would miss by the calibration error.
    F0 = T_uf @ T_tg[0] @ np.linalg.inv(T_TOOL)
    got0 = calibrated_flange(cal, _controller(robot, F0, q[0])[None])[0] @ T_TOOL
    assert np.linalg.norm(got0[:3, 3] - (T_uf @ T_tg[0])[:3, 3]) * 1e3 > 0.3


def test_frame_algebra_is_the_nominal_fk_for_nominal_parameters(tracker_twin, rng):
    cal = tracker_twin.calibrated
    nominal = dataclasses.replace(cal, params=cal.model.nominal.copy())
    q = box_poses(rng, 20)
    np.testing.assert_allclose(
        calibrated_flange(nominal, q), cal.model.robot.fk_flange(q), atol=1e-12
    )


def _krl_joints(q_deg):
    lines = ["DEFDAT HOMES"]
    for i, q in enumerate(q_deg):
        vals = ",".join(f"A{k + 1} {v:.4f}" for k, v in enumerate(q))
        lines.append(f"DECL E6AXIS XHOME{i}={{{vals},E1 0.0}}")
    return "\n".join([*lines, "ENDDAT", ""])


def test_issue_34_wrist_singular_joint_targets_least_motion(
    tracker_twin, model_file, run_cli, tmp_path, rng
):
    """HOME (J5 = 0) and J4 = J5 = 0 points: corrected with sub-degree joint motion, not
    refused, a warning naming the turn given up; an ordinary point moves nothing far."""
    cal = tracker_twin.calibrated
    q_deg = np.array(
        [[0, 0, 0, 0, 0, 0], [10, 20, -10, 0, 0, 30], [-20, 30, -20, 0, 0.02, 0],
         [15, 25, -15, 40, -60, 10]], float,
    )  # fmt: skip
    src, out = tmp_path / "homes.dat", tmp_path / "c.dat"
    src.write_text(_krl_joints(q_deg))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--report", str(tmp_path / "r.csv"), "--json",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rows = [r.split(",") for r in (tmp_path / "r.csv").read_text().splitlines()]
    head = rows[0]
    dq = np.array([float(r[head.index("dq_max_deg")]) for r in rows[1:]])
    err = np.array([float(r[head.index("err_mm")]) for r in rows[1:]])
    rot = np.array([float(r[head.index("rot_err_deg")]) for r in rows[1:]])
    assert [r[-1] for r in rows[1:]] == ["ok"] * 4
    n = 6
    q0 = np.array([[float(v) for v in r[2 : 2 + n]] for r in rows[1:]])
    q1 = np.array([[float(v) for v in r[2 + n : 2 + 2 * n]] for r in rows[1:]])
    # No J4/J6 swing for a sub-millimetre correction: the singular rows move their joints
    # as little as the ordinary one (the calibrated joint offsets, about half a degree).
    assert dq.max() < 1.0, dq
    assert np.abs(q1 - q0)[:3, [3, 5]].max() < 1.0
    # Without the least-motion rule the exact orientation is not met (the issue's
    # exit 4) or costs a wrist swing.
    from kinecal.compensation import compensate, program_targets

    qr = np.radians(q0[:3])
    p_t, R_t = program_targets(cal, qr)
    exact = compensate(cal, p_t, qr, R_target=R_t, least_motion_deg=None)
    swing = np.degrees(np.abs(exact.joint_change)).max(axis=1)
    assert ((exact.status != "ok") | (swing > 2.0)).any(), (exact.status, swing)
    assert err.max() < 1e-3  # the position is met
    assert rot[:3].max() < 0.1 and rot[3] < 1e-6  # a tiny turn given up, where singular
    assert res.stderr.count("next to a singular pose") >= 2
    # The joint-motion warning: every correction moves more than 0.001 deg.
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out",
        str(tmp_path / "c2.dat"), "--warn-dq-deg", "0.001",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert res.stderr.count("(more than --warn-dq-deg 0.001)") == 4


def test_issue_34_cartesian_target_at_a_straight_wrist(
    tracker_twin, model_file, run_cli, tmp_path
):
    """A Cartesian target taught at J5 = 0.01 deg: reached within 0.01 mm in position with
    no joint moving more than a degree (the calibrated offsets are about half a degree)."""
    cal = tracker_twin.calibrated
    q = np.radians(
        [[5.0, 15.0, -20.0, 0.0, -0.01, 20.0], [5.0, 15.0, -20.0, 30, -45, 20]]
    )
    T_tg = _targets(cal, q)
    src, out = tmp_path / "w.ls", tmp_path / "cw.ls"
    three = np.concatenate([q, q[:1]])  # the third names UF 3: left
    src.write_bytes(_fanuc(cal, three, _targets(cal, three)).encode())
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--report", str(tmp_path / "r.csv"), "--decimals", "6", *FRAME_ARGS["fanuc-ls"](),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rows = [r.split(",") for r in (tmp_path / "r.csv").read_text().splitlines()]
    head = rows[0]
    assert [r[-1] for r in rows[1:]] == ["left", "ok", "ok", "left"]  # PR[5] first
    dq = [float(r[head.index("dq_max_deg")]) for r in rows[2:4]]
    assert max(dq) < 1.0, dq  # the calibrated joint offsets, no wrist swing
    vals, _ = _written_targets("fanuc-ls", out.read_text())
    F = T_UF @ _read_pose("fanuc-ls", vals[0]) @ np.linalg.inv(T_TOOL)
    q_ctrl = _controller(cal.model.robot, F, q[0])
    got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
    assert np.linalg.norm(got[:3, 3] - (T_UF @ T_tg[0])[:3, 3]) * 1e3 < 0.01


@pytest.mark.parametrize(
    ("fmt", "old", "new", "message"),
    [
        ("fanuc-ls", "CONFIG : '", "CONFIG : 'X", r"cart.ls: line 7: P\[1\] CONFIG 'X"),
        (
            "fanuc-ls",
            "W = ",
            "Q = ",
            r"cart.ls: line 5: P\[1\] has no 'W = <number> deg'",
        ),
        ("krl", ",B ", ",Q ", r"cart.dat: line 2: a Cartesian aggregate without B"),
        ("rapid", "],[0", "],[", r"cart.mod: line \d+: robtarget p0: expected \[\[x"),
    ],
)
def test_issue_34_malformed_cartesian_targets_name_file_and_line(
    tracker_twin, model_file, run_cli, tmp_path, fmt, old, new, message
):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(3), 2)
    writer, ext = WRITERS[fmt]
    text = writer(cal, q, _targets(cal, q))
    if fmt == "rapid":  # the confdata of the first robtarget loses a number
        at = text.index("CONST robtarget p0")
        cut = text.index("],[", text.index("],[", at) + 3)
        text = text[:cut] + "],[" + text[cut + 5 :]
    else:
        text = text.replace(old, new, 1)
    src = tmp_path / f"cart{ext}"
    src.write_bytes(text.encode())
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out",
        str(tmp_path / f"o{ext}"), *FRAME_ARGS[fmt](),
    )  # fmt: skip
    assert res.returncode != 0
    assert re.search(message, res.stderr), res.stderr
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--uframe", "1=1,2,3"], r"--uframe '1=1,2,3': expected ID=v,v,v,v,v,v"),
        (["--utool", "1=1,2,3,4,5,nan"], r"--utool '1=1,2,3,4,5,nan': expected"),
    ],
)
def test_issue_34_bad_frame_options(
    tracker_twin, model_file, run_cli, tmp_path, args, message
):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(3), 2)
    src = tmp_path / "cart.ls"
    src.write_bytes(_fanuc(cal, q, _targets(cal, q)).encode())
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out",
        str(tmp_path / "o.ls"), *args,
    )  # fmt: skip
    assert res.returncode != 0 and re.search(message, res.stderr), res.stderr
    assert not (tmp_path / "o.ls").exists()


def test_issue_34_frames_file_and_unreachable_targets_counted(
    tracker_twin, model_file, run_cli, tmp_path
):
    """Frames from a YAML file; targets taught at J5's limits cannot all be reached by
    the calibrated robot (exit 4, nothing written; with --allow-unreachable written and
    flagged); a target 3 m away has no nominal solution: left, with the reason."""
    cal = tracker_twin.calibrated
    lim = cal.model.robot.limits
    q = _taught(np.random.default_rng(5), 5)
    q[2, 4] = lim[4, 0] + 1e-7  # taught at J5's limit: the nominal robot reaches it
    T_tg = _targets(cal, q)
    # Target 2: the calibrated robot needs J5 0.05 deg beyond a limit where the nominal
    # one is inside (the first pose of the candidates where that holds).
    for cand in _taught(np.random.default_rng(6), 40):
        side = 1 if cand[4] > 0 else 0
        cand[4] = lim[4, side] + np.radians(0.05) * (1 if side else -1)
        F = calibrated_flange(cal, cand[None])[0]
        q_nom = _controller(cal.model.robot, F, cand)
        if lim[4, 0] + 1e-4 < q_nom[4] < lim[4, 1] - 1e-4:
            break
    else:
        raise AssertionError("no candidate")
    q[1] = q_nom
    T_tg[1] = np.linalg.inv(T_UF) @ F @ T_TOOL
    T_tg[3, :3, 3] += [3.0, 0.0, 0.0]
    src = tmp_path / "cart.dat"
    src.write_text(_krl(cal, q, T_tg))
    uf = ", ".join(f"{x:.9f}" for x in _numbers("krl", T_UF))
    tl = ", ".join(f"{x:.9f}" for x in _numbers("krl", T_TOOL))
    frames = tmp_path / "frames.yaml"
    frames.write_text(f"uframe:\n  1: [{uf}]\nutool:\n  2: [{tl}]\n")
    # The controller's own $config.dat gives the same frames.
    body = lambda v: ",".join(f"{k} {x:.9f}" for k, x in zip("XYZABC", v))  # noqa: E731
    config = tmp_path / "$config.dat"
    config.write_text(
        "DEFDAT  $CONFIG\nDECL FRAME BASE_DATA[1]={" + body(_numbers("krl", T_UF))
        + "}\nTOOL_DATA[2]={" + body(_numbers("krl", T_TOOL)) + "}\nENDDAT\n"
    )  # fmt: skip
    via_config = run_cli(
        "compensate", str(src), "--out", str(tmp_path / "v.dat"), "--model",
        str(model_file), "--frames", str(config), "--allow-unreachable",
    )  # fmt: skip
    assert via_config.returncode == 0, via_config.stderr
    args = ["--model", str(model_file), "--frames", str(frames), "--json"]
    res = run_cli("compensate", str(src), "--out", str(tmp_path / "o.dat"), *args)
    assert res.returncode == 4, res.stderr
    assert not (tmp_path / "o.dat").exists()
    res = run_cli(
        "compensate", str(src), "--out", str(tmp_path / "o.dat"), *args,
        "--allow-unreachable",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["n"] == 5 and summary["left"] == 1
    assert summary["unreachable"] >= 1 and summary["ok"] == 4 - summary["unreachable"]
    assert "line 8 (XP4): left as written: no nominal joint solution" in res.stderr
    vals, _ = _written_targets("krl", (tmp_path / "o.dat").read_text())
    vals0, _ = _written_targets("krl", src.read_text())
    assert vals[3] == vals0[3] and vals[0] != vals0[0]
    assert (tmp_path / "v.dat").read_text() == (tmp_path / "o.dat").read_text()


def test_issue_34_flags_pick_one_solution_of_eight(tracker_twin):
    """The flags of a pose's joints select those joints again among the pose's nominal
    solutions (front/back, elbow, wrist flip, turns), in the three flagged formats; the
    LR Mate's standard pose reads N U T (tool down, J5 = -90 deg)."""
    from kinecal.compensation._cartesian import branch_solutions
    from kinecal.compensation._configs import config_accept

    cal = tracker_twin.calibrated
    robot = cal.model.robot
    q = _taught(np.random.default_rng(8), 12)
    q[:4, 0] += np.radians(100.0) * np.sign(q[:4, 0])  # far round J1
    q[4:8, 3] = np.radians([150.0, -150.0, 170.0, -170.0])  # J4 by the half turn
    q[8:, 5] = np.radians([200.0, -200.0, 300.0, -300.0])  # J6 past a half turn
    q = np.clip(q, robot.limits[:, 0], robot.limits[:, 1])
    F = robot.fk_flange(q)
    for fmt in ("fanuc-ls", "krl", "rapid"):
        flags = encode_config(cal, fmt, q)
        got, found = branch_solutions(cal, F, config_accept(cal, fmt, flags))
        assert found.all(), fmt
        np.testing.assert_allclose(got, q, atol=1e-6, err_msg=fmt)
    assert encode_config(cal, "fanuc-ls", np.radians([[0, 0, 0, 0, -90, 0]]))[0] == (
        "N", "U", "T", 0, 0, 0,
    )  # fmt: skip
    assert (
        encode_config(cal, "fanuc-ls", np.radians([[0, 0, 0, 0, -90, 200]]))[0][5] == 1
    )


def test_issue_34_urscript_pose_after_a_joint_move(
    tracker_twin, model_file, run_cli, tmp_path
):
    """``movel(p[...])`` with no waypoint joints starts from the movej before it, as the
    controller does; a pose before any joint move is left, with the reason."""
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(11), 3)
    T = cal.model.robot.fk_flange(q + np.radians(2.0)) @ T_TOOL  # 2 deg from the movej
    tcp = ", ".join(f"{x:.9f}" for x in _numbers("urscript", T_TOOL))

    def pose(k):
        return ", ".join(f"{x:.9f}" for x in _numbers("urscript", T[k]))

    lines = ["def p():", f"  set_tcp(p[{tcp}])", f"  movel(p[{pose(2)}], a=1, v=0.1)"]
    for k in range(2):
        lines.append(f"  movej([{', '.join(f'{v:.6f}' for v in q[k])}], a=1, v=0.5)")
        lines.append(f"  movel(p[{pose(k)}], a=1, v=0.1)")
    src, out = tmp_path / "p.script", tmp_path / "c.script"
    src.write_text("\n".join([*lines, "end", ""]))
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out), "--json"
    )
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert summary["n"] == 5 and summary["ok"] == 4 and summary["left"] == 1
    assert (
        "line 3 (movel): left as written: no configuration and no earlier" in res.stderr
    )
    new = re.findall(r"movel\(p\[([^\]]*)\]", out.read_text())
    for k in range(2):
        T_new = _read_pose("urscript", [float(v) for v in new[k + 1].split(",")])
        q_ctrl = _controller(cal.model.robot, T_new @ np.linalg.inv(T_TOOL), q[k])
        got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
        assert np.linalg.norm(got[:3, 3] - T[k][:3, 3]) * 1e3 < 0.01


def test_issue_34_readers_find_the_active_frames():
    """KRL: the BASE/TOOL set last before a target ($BASE = BASE_DATA[n], BAS(#TOOL, n));
    RAPID: the tool of a move whose other arguments hold commas (Offs(..))."""
    from kinecal.io._cartesian_programs import read_cartesian

    krl = (
        "DEF x()\n$BASE = BASE_DATA[3]\nBAS(#TOOL, 2)\n"
        "LIN {X 100, Y 0, Z 500, A 0, B 90, C 0}\n$TOOL=TOOL_DATA[4]\n"
        "PTP {POS: X 100, Y 0, Z 500, A 0, B 90, C 0, S 2, T 3}\nEND\n"
    )
    got = [(c.line, c.frame, c.tool, c.config) for c in read_cartesian(krl, "krl")]
    assert got == [(4, "3", "2", None), (6, "3", "4", (2, 3))]
    rapid = (
        "CONST robtarget p10:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
        "MoveL Offs(p10, 0, 0, 50), v100, fine, tA\\WObj:=w1;\n"
        "MoveL p10, v100, z10, tGrip\\WObj:=w1;\n"
    )
    (pt,) = read_cartesian(rapid, "rapid")
    assert (pt.tool, pt.frame, pt.config, pt.why_not) == (
        "tGrip",
        "w1",
        (0, 0, 0, 0),
        "",
    )


@pytest.mark.parametrize("fmt", ["fanuc-ls", "krl"])
def test_issue_34_correction_across_j5_zero_rewrites_the_flags(
    tracker_twin, model_file, run_cli, tmp_path, fmt
):
    """Taught at J5 = +0.01 deg, the calibrated robot needs J5 on the other side of 0:
    the target is corrected, its flags name the new side (a warning says so), and the
    controller reading them reaches the taught pose within 0.01 mm."""
    cal = tracker_twin.calibrated
    q = np.radians(
        [[5.0, 15.0, -20.0, 0.0, 0.01, 20.0], [5.0, 15.0, -20.0, 30, 45, 20]]
    )
    writer, ext = WRITERS[fmt]
    T_tg = _targets(cal, q)
    src, out = tmp_path / f"x{ext}", tmp_path / f"c{ext}"
    src.write_bytes(
        writer(
            cal, np.concatenate([q, q[:1]]), np.concatenate([T_tg, T_tg[:1]])
        ).encode()
    )
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--decimals", "6", "--json", *FRAME_ARGS[fmt](),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "the correction crosses a configuration boundary" in res.stderr
    vals, flags = _written_targets(fmt, out.read_text())
    _, flags0 = _written_targets(fmt, src.read_text())
    assert flags[0] != flags0[0] and flags[1] == flags0[1]
    F = T_UF @ _read_pose(fmt, vals[0]) @ np.linalg.inv(T_TOOL)
    q_ctrl = _controller(cal.model.robot, F, q[0] - [0, 0, 0, 0, np.radians(0.5), 0])
    assert q_ctrl[4] < 0  # the side the flags now name
    if fmt == "fanuc-ls":  # F (J5 >= 0) -> N
        assert flags0[0][0] == "F" and flags[0][0] == "N"
    else:  # T bit 4: A5 < 0
        t0, t1 = (int(f.split("T ")[1]) for f in (flags0[0], flags[0]))
        assert not t0 & 16 and t1 & 16
    got = calibrated_flange(cal, q_ctrl[None])[0] @ T_TOOL
    assert np.linalg.norm(got[:3, 3] - (T_UF @ T_tg[0])[:3, 3]) * 1e3 < 0.01
