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
from tests.compensation.conftest import box_poses

_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def _pose(xyz_m, rotvec) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    T[:3, 3] = xyz_m
    return T


T_UF = _pose([0.35, -0.12, 0.08], [0.02, -0.03, 0.4])  # a user frame on the table
T_TOOL = _pose([0.01, 0.0, 0.12], [0.0, 0.25, 0.0])  # a tilted tool, 120 mm out


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
