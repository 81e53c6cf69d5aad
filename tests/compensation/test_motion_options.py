"""Motion options whose target is no pose to correct (FANUC, KRL): an incremental move (INC)
moves by its P[] (a displacement from where the robot is, in joints or XYZWPR), a
vision offset (VOFFSET, or an OFFSET CONDITION on a vision register VR[]) is measured
as the program runs. Such targets were corrected as absolute poses (an INC P[] of J3 =
-5 deg became -4.798 deg). Now each is counted and left as written with its reason; the
other targets of the program are corrected as before."""

from __future__ import annotations

import json
import re

import numpy as np

from tests.compensation.test_issue_34_cartesian import (
    FRAME_ARGS,
    WRITERS,
    _targets,
    _taught,
)


def _with_moves(text: str, moves: list[str]) -> str:
    mn = [f"{k + 1:4d}:{m} ;" for k, m in enumerate(moves)]
    return text.replace("/MN\r\n", "/MN\r\n" + "\r\n".join(mn) + "\r\n", 1)


def test_incremental_and_vision_offset_targets_are_left(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(8), 5)
    text = WRITERS["fanuc-ls"][0](cal, q, _targets(cal, q))
    text = _with_moves(text, [
        "  UFRAME_NUM=1", "  UTOOL_NUM=1",
        "J P[1] 100% FINE", "L P[2] 100mm/sec FINE INC",
        "L P[3] 100mm/sec CNT50 VOFFSET,VR[1]",
        "  OFFSET CONDITION VR[2]", "L P[4] 100mm/sec FINE Offset",
    ])  # fmt: skip
    src, out = tmp_path / "opts.ls", tmp_path / "out.ls"
    src.write_bytes(text.encode())
    res = run_cli(
        "compensate", src, "--model", model_file, "--out", out, "--json",
        *FRAME_ARGS["fanuc-ls"](), "--allow-unreachable",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    err = res.stderr
    assert "(P[2]): left as written: an incremental move (INC)" in err
    assert "(P[3]): left as written: a vision offset (VOFFSET)" in err
    assert "(P[4]): left as written: Offset (CONDITION VR[]): a vision register" in err
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    # P[1] corrected; P[2..4] left; P[5] names UF 3 (not given) and the writer's PR[5].
    assert summary["ok"] == 1 and summary["left"] == 5, summary

    def values(t, n):
        rec = re.search(rf"P\[{n}\]\{{(.*?)\}};", t, re.S)
        assert rec is not None
        return rec.group(1)

    new = out.read_bytes().decode()
    assert values(new, 1) != values(text, 1)
    for n in (2, 3, 4):
        assert values(new, n) == values(text, n)


def test_an_incremental_joint_target_is_left(model_file, run_cli, tmp_path):
    joints = ("J1=10.000 deg, J2=20.000 deg, J3=-30.000 deg, J4=10.000 deg, "
              "J5=-40.000 deg, J6=15.000 deg")  # fmt: skip
    inc = ("J1=0.000 deg, J2=0.000 deg, J3=-5.000 deg, J4=0.000 deg, J5=10.000 deg, "
           "J6=0.000 deg")  # fmt: skip
    text = "\n".join([
        "/PROG  INCJ", "/MN", "   1:J P[1] 100% FINE ;", "   2:J P[2] 100% FINE INC ;",
        "/POS", "P[1]{", "   GP1:", "\tUF : 0, UT : 0,", f"\t{joints}", "};",
        "P[2]{", "   GP1:", "\tUF : 0, UT : 0,", f"\t{inc}", "};", "/END", "",
    ])  # fmt: skip
    src, out = tmp_path / "incj.ls", tmp_path / "out.ls"
    src.write_text(text)
    res = run_cli("compensate", src, "--model", model_file, "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    assert "(P[2]): left as written: an incremental move (INC) uses it" in res.stderr
    assert "1 joint targets corrected, 1 left as written" in res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert (summary["n"], summary["ok"], summary["left"]) == (2, 1, 1)
    new = out.read_text()
    assert inc in new and joints not in new


def test_krl_relative_and_partial_motions_are_left(model_file, run_cli, tmp_path):
    """KRL: ``PTP_REL``/``LIN_REL`` move by their aggregate; ``PTP {A1 45}`` and ``LIN
    {Z 300}`` keep the robot's current values for what they leave out. A valid program
    with them was refused ("a Cartesian aggregate without Y") or read a one-axis
    aggregate as a joint target; now they are counted and left, the full targets
    corrected."""
    text = "\n".join([
        "DEF rel()",
        "  PTP {A1 10, A2 -80, A3 90, A4 0, A5 30, A6 0}",
        "  PTP_REL {A3 -5}",
        "  LIN_REL {X 10, Z -20}",
        "  PTP {A1 45}",
        "  LIN {Z 300}",
        "  PTP {A1 20, A2 -70, A3 80, A4 10, A5 40, A6 5}",
        "END", "",
    ])  # fmt: skip
    src, out = tmp_path / "rel.src", tmp_path / "out.src"
    src.write_text(text)
    res = run_cli("compensate", src, "--model", model_file, "--out", out, "--json")
    assert res.returncode == 0, res.stderr
    err = res.stderr
    assert "line 3 (PTP_REL): left as written: a relative motion (PTP_REL)" in err
    assert "line 4 (LIN_REL): left as written: a relative motion (LIN_REL)" in err
    assert err.count("left as written: a partial aggregate") == 2
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert (summary["n"], summary["ok"], summary["left"]) == (6, 2, 4)
    new = out.read_text().splitlines()
    old = text.splitlines()
    assert new[2:6] == old[2:6] and new[1] != old[1] and new[6] != old[6]


def test_rapid_trigger_search_and_process_moves_use_their_robtargets(
    tracker_twin, model_file, run_cli, tmp_path
):
    """RAPID targets moved to by TriggL, SearchL (ToPoint after the signal and the
    search point), ArcL or MoveLSync, with optional arguments anywhere, are corrected
    in their tool and wobj like MoveL's (they were left: "no move instruction uses
    it")."""
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(21), 4)
    text = WRITERS["rapid"][0](cal, q, _targets(cal, q))
    moves = [
        "  TriggL p0, v200, gunon, \\T2:=gunoff, z10, tGrip\\WObj:=wTable;",
        "  SearchL \\Stop, di1, sp1, p1, v100, tGrip\\WObj:=wTable;",
        "  ArcL p2, v100, seam1, weld1, weave1, fine, tGrip\\WObj:=wTable;",
        '  MoveLSync p3, v200, fine, tGrip\\WObj:=wTable, \\ID:=10, "proc";',
    ]
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("MoveL ")]
    at = lines.index("PROC main()") + 1
    src, out = tmp_path / "trig.mod", tmp_path / "out.mod"
    src.write_text("\n".join([*lines[:at], *moves, *lines[at:]]) + "\n")
    res = run_cli(
        "compensate", src, "--model", model_file, "--out", out, "--json",
        *FRAME_ARGS["rapid"](),
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    summary = json.loads(res.stdout.strip().splitlines()[-1])
    assert (summary["n"], summary["ok"], summary["left"]) == (4, 4, 0), res.stderr
    assert "largest error of the calibrated robot" in res.stderr
