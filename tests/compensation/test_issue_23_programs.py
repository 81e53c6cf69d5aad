"""Issue 23, item 4: `kinecal compensate` on robot programs, on the tracker twin.

A program's joint targets were taught on the nominal robot; compensated, the true robot
must put its tool where the nominal robot (hanging from the calibrated base, carrying the
calibrated tool) would have.
"""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.compensation import program_targets
from kinecal.io._programs import program_joints, read_program
from tests.compensation.conftest import box_poses, stretched_poses
from tests.helpers import unmarked


def _fanuc(q_deg):
    out = ["/PROG  COMP_TEST", "/ATTR", "/MN"]
    out += [f"   {i + 1}:J P[{i + 1}] 100% FINE    ;" for i in range(len(q_deg))]
    out.append("/POS")
    for i, q in enumerate(q_deg):
        j = [f"J{k + 1}={v:10.3f} deg" for k, v in enumerate(q)]
        out += [f"P[{i + 1}]{{", "   GP1:", "\tUF : 1, UT : 1,\t"]
        out += ["\t" + ",\t".join(j[:3]) + ",", "\t" + ",\t".join(j[3:]), "};"]
    out.append("/END")
    return "\r\n".join(out) + "\r\n"


def _urscript(q_deg):
    lines = ["def comp_test():"]
    for q in np.radians(q_deg):
        lines.append(f"  movej([{', '.join(f'{v:.6f}' for v in q)}], a=1.2, v=0.5)")
    return "\n".join([*lines, "end", ""])


def _rapid(q_deg):
    lines = ["MODULE CompTest"]
    for i, q in enumerate(q_deg):
        vals = ",".join(f"{v:.4f}" for v in q)
        lines.append(
            f"    CONST jointtarget j{i}:=[[{vals}],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];"
        )
    return "\n".join([*lines, "ENDMODULE", ""])


def _krl(q_deg):
    lines = ["DEFDAT COMP_TEST"]
    for i, q in enumerate(q_deg):
        vals = ",".join(f"A{k + 1} {v:.4f}" for k, v in enumerate(q))
        lines.append(f"DECL E6AXIS XP{i}={{{vals},E1 0.0,E2 0.0}}")
    return "\n".join([*lines, "ENDDAT", ""])


WRITERS = {".ls": _fanuc, ".script": _urscript, ".mod": _rapid, ".dat": _krl}


def _program_poses(rng, n):
    return np.concatenate([stretched_poses(rng, n // 4), box_poses(rng, n - n // 4)])


def test_issue_23_fanuc_program_compensated_on_the_twin(
    tracker_twin, model_file, run_cli, tmp_path, rng
):
    twin, cal = tracker_twin, tracker_twin.calibrated
    q_prog = np.round(np.degrees(_program_poses(rng, 40)), 3)  # as taught: 0.001 deg
    src = tmp_path / "prog.ls"
    src.write_bytes(_fanuc(q_prog).encode())
    out, report = tmp_path / "corrected.ls", tmp_path / "report.csv"
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--report", str(report), "--decimals", "6",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    q0 = program_joints(read_program(src), cal.model.robot)
    q1 = program_joints(read_program(out), cal.model.robot)
    p_want, _ = program_targets(cal, q0)
    err = lambda q: np.linalg.norm(twin.truth.evaluate(q)[0] - p_want, axis=1) * 1e3  # noqa: E731
    e0, e1 = err(q0), err(q1)
    assert np.sqrt(np.mean(e1**2)) <= 0.015 and e1.max() <= 0.05
    assert np.sqrt(np.mean(e0**2)) > 30 * np.sqrt(np.mean(e1**2))  # uncompensated: ~mm
    # The report: one row per point, program and written joints, all reached.
    rows = report.read_text().splitlines()
    assert rows[0].startswith("point,line,j1_program") and rows[0].endswith(
        "err_mm,status"
    )
    assert len(rows) == 41 and all(r.endswith(",ok") for r in rows[1:])
    np.testing.assert_allclose(
        np.array([[float(v) for v in r.split(",")[2:8]] for r in rows[1:]]),
        q_prog,
        atol=1e-9,
    )
    # At the file's own precision (0.001 deg) the rounding costs a few micrometres.
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(tmp_path / "c3.ls"),
        "--report", str(tmp_path / "r3.csv"),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    head = (tmp_path / "r3.csv").read_text().splitlines()[0].split(",")
    k = head.index("err_written_mm")
    written = [
        float(r.split(",")[k])
        for r in (tmp_path / "r3.csv").read_text().splitlines()[1:]
    ]
    assert max(written) < 0.02
    e3 = err(program_joints(read_program(tmp_path / "c3.ls"), cal.model.robot))
    assert np.sqrt(np.mean(e3**2)) <= 0.015


@pytest.mark.parametrize("ext", [".script", ".mod", ".dat"])
def test_other_program_formats_through_the_cli(
    tracker_twin, model_file, run_cli, tmp_path, rng, ext
):
    cal = tracker_twin.calibrated
    q_prog = np.degrees(box_poses(rng, 8))
    src = tmp_path / f"prog{ext}"
    src.write_text(WRITERS[ext](q_prog))
    out = tmp_path / f"corrected{ext}"
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out), "--json"
    )
    assert res.returncode == 0, res.stderr
    q0 = program_joints(read_program(src), cal.model.robot)
    q1 = program_joints(read_program(out), cal.model.robot)
    p_want, _ = program_targets(cal, q0)
    e = np.linalg.norm(tracker_twin.truth.evaluate(q1)[0] - p_want, axis=1) * 1e3
    assert e.max() < 0.03
    assert 0.01 < np.degrees(np.abs(q1 - q0)).max() < 2.0
    new = unmarked(out.read_text(), src.read_text())
    assert len(new.splitlines()) == len(src.read_text().splitlines())


def test_unreachable_program_points_keep_their_joints(
    tracker_twin, model_file, run_cli, tmp_path, rng
):
    """A point whose correction needs J5 past its limit (125 deg) is flagged, named, and
    (with --allow-unreachable) left as programmed."""
    from kinecal.compensation import compensate

    cal = tracker_twin.calibrated
    cand = box_poses(rng, 30)
    cand[:, 4] = np.radians(124.0)
    p, R = program_targets(cal, cand)
    free = compensate(cal, p, cand, R_target=R)
    d5 = np.degrees(free.q_ctrl[:, 4] - cand[:, 4])
    k = int(np.argmax(d5))
    assert d5[k] > 0.02  # some correction turns J5 outwards
    q_prog = np.degrees(box_poses(rng, 3))
    q_prog[1] = np.degrees(cand[k])
    q_prog[1, 4] = 125.0 - d5[k] / 2  # inside the limit; its correction is not
    src = tmp_path / "p.ls"
    src.write_bytes(_fanuc(q_prog).encode())
    out = tmp_path / "c.ls"
    res = run_cli("compensate", str(src), "--model", str(model_file), "--out", str(out))
    assert res.returncode == 4 and not out.exists(), res.stderr
    assert "(P[2]): joint_limit (J5 beyond its limit)" in res.stderr
    res = run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--allow-unreachable",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    q0 = program_joints(read_program(src), cal.model.robot)
    q1 = program_joints(read_program(out), cal.model.robot)
    np.testing.assert_array_equal(q1[1], q0[1])  # flagged: left as programmed
    assert np.abs(q1[[0, 2]] - q0[[0, 2]]).max() > 0


def test_csv_keeps_the_program_joints_beside_the_corrected(
    tracker_twin, model_file, run_cli, tmp_path, rng
):
    """CORRECTED.csv: corrected joints stay in j*_deg (the contract), the originals move
    to j*_deg_program, every diagnostic is numeric, err_mm and status stay last."""
    twin = tracker_twin
    goal = _program_poses(rng, 24)
    p = twin.truth.evaluate(goal)[0] * 1e3
    prog = np.degrees(goal + np.radians(0.2) * rng.standard_normal(goal.shape))
    head = "x_mm,y_mm,z_mm," + ",".join(f"j{k}_deg" for k in range(1, 7)) + ",note"
    lines = [head] + [
        ",".join(f"{v:.6f}" for v in (*pi, *qi)) + f",pt{i}"
        for i, (pi, qi) in enumerate(zip(p, prog))
    ]
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n")
    res = run_cli(
        "compensate", str(tmp_path / "t.csv"), "--model", str(model_file),
        "--out", str(tmp_path / "c.csv"),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    rows = (tmp_path / "c.csv").read_text().splitlines()
    h = rows[0].split(",")
    assert h[:10] == head.split(",")
    assert h[10:] == [f"j{k}_deg_program" for k in range(1, 7)] + [
        "rot_err_deg", "dq_max_deg", "cond", "limit_joint", "err_mm", "status",
    ]  # fmt: skip
    body = [r.split(",") for r in rows[1:]]
    assert [r[9] for r in body] == [f"pt{i}" for i in range(24)]
    num = np.array([[float(v) for i, v in enumerate(r[:-1]) if i != 9] for r in body])
    np.testing.assert_allclose(num[:, 9:15], prog, atol=5e-7)  # the program, kept
    q = np.radians(num[:, 3:9])
    err = np.linalg.norm(twin.truth.evaluate(q)[0] * 1e3 - p, axis=1)
    assert np.sqrt(np.mean(err**2)) <= 0.015 and err.max() <= 0.05
    assert (num[:, -1] < 1e-6).all() and (num[:, -2] == 0).all()  # err_mm, limit_joint
    assert (num[:, -3] >= 1).all()  # cond
    assert all(r[-1] == "ok" for r in body)
