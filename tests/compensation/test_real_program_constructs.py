"""Constructs of real programs (controller backups and offline exports on GitHub, run
through `compensate` in the audit of issue 34), rebuilt here as small synthetic programs:

- comments hold no targets: a commented-out move or aggregate (RAPID ``!``, KRL ``;``,
  URScript ``#``, FANUC ``!`` / ``//``) was counted, made other targets "left", or was
  itself corrected inside the comment;
- FANUC: an untaught position (``UF : F, UT : F``, ``X = ********``) or one written as
  ``RX = ..`` refused the whole file or was not counted; a German-language export
  (``KONFIG``) was refused; a target of a coordinated move (``COORD``) or with an
  integrated extended axis (``E1 = .. mm``) was corrected as if the robot base were
  fixed;
- RAPID: the elements of a robtarget array and robtargets without a value in the file
  (``CRobT()``, another module) were not counted; ``MoveLDO`` read the signal's value
  as the tool; a robtarget with external axes set (a track) or that the program assigns
  (``p.trans.z := ..``, ``p := Offs(..)``) was corrected;
- KRL: an E6POS with E1..E6 set likewise; a motion to a point declared elsewhere
  (``PTP XP1`` in the .src, ``PTP XHOME``) was not counted.
Each is now counted and left with its reason, or not a target at all (a comment); the
other targets are corrected as before and the file is kept byte for byte elsewhere."""

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
from tests.helpers import unmarked


def _run(run_cli, model, tmp_path, fmt, text, name, *extra):
    src, out = tmp_path / name, tmp_path / ("out_" + name)
    src.write_bytes(text.encode("utf-8", errors="surrogateescape"))
    res = run_cli(
        "compensate", src, "--model", model, "--out", out,
        "--json", "--allow-unreachable", *FRAME_ARGS.get(fmt, list)(), *extra,
    )  # fmt: skip
    return res, out


def _summary(res):
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def _same_outside(old: str, new: str, changed: list[int]) -> None:
    """Lines of ``new`` equal those of ``old`` except the 1-based ``changed`` ones (and
    the comment line that marks ``new`` compensated)."""
    a, b = old.splitlines(), unmarked(new, old).splitlines()
    assert len(a) == len(b)
    diff = [k + 1 for k, (x, y) in enumerate(zip(a, b)) if x != y]
    assert set(diff) <= set(changed), diff


def test_fanuc_untaught_other_kinds_coord_rail_comments_and_german(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(3), 4)
    text = WRITERS["fanuc-ls"][0](cal, q, _targets(cal, q))
    # P[2] as a German-language controller writes it; P[4] names UF 3 (not given).
    text = text.replace("P[2]{\r\n   GP1:\r\n\tUF : 1, UT : 1,\t\tCONFIG",
                        "P[2]{\r\n   GP1:\r\n\tUF : 1, UT : 1,\t\tKONFIG")  # fmt: skip
    p1 = re.search(r"P\[1\]\{.*?\};\r\n", text, re.S).group(0)
    rail = p1.replace("P[1]", "P[12]").replace(
        " deg\r\n};", " deg,\r\n\tE1= -1100.000  mm\r\n};"
    )
    extra = (
        "P[10]{\r\n   GP1:\r\n\tUF : F, UT : F,\t\tCONFIG : 'N D B, 0, 0, 0',\r\n"
        "\tX = ********  mm,\tY = ********  mm,\tZ = ********  mm,\r\n"
        "\tW = ******** deg,\tP = ******** deg,\tR = ******** deg\r\n};\r\n"
        "P[11]{\r\n   GP1:\r\n\tUF : 1, UT : 1,\t\tCONFIG : 'N U T, 0, 0, 0',\r\n"
        "\tRX =   172.722  mm,\tRY = -1615.912  mm,\tRZ =  -927.308  mm,\r\n"
        "\tRW =   154.724 deg,\tRP =    71.404 deg,\tRR =   175.445 deg\r\n};\r\n"
    ) + rail
    p4 = re.search(r"P\[4\]\{.*?\r\n\};", text, re.S).group(0)
    gp2 = p4.split("GP1:")[1].replace("\r\n};", "")
    text = text.replace(p4, p4.replace("\r\n};", "\r\n   GP2:" + gp2 + "\r\n};"))
    text = text.replace("/END", extra + "/END")
    moves = [
        "   2:  !L P[2] 100mm/sec FINE COORD ;",  # a comment: not P[2]'s move
        "   3:  //L P[1] 100mm/sec FINE Offset,PR[9] ;",  # commented out
        "   4:L P[1] 100mm/sec FINE ;",
        "   5:L P[3] 100mm/sec FINE COORD ;",
        "   6:L P[12] 100mm/sec FINE ;",
        "   7:  BENUTZER_NUM=1 ;",
        "   8:  WKZ_NUM=1 ;",
    ]
    text = text.replace(
        "FINE    ;\r\n/POS", "FINE    ;\r\n" + "\r\n".join(moves) + "\r\n/POS"
    )
    res, out = _run(run_cli, model_file, tmp_path, "fanuc-ls", text, "real.ls")
    summary = _summary(res)
    err = res.stderr
    assert "(P[10]): left as written: not taught" in err
    assert "(P[11]): left as written: its values are written as RX, RY" in err
    assert "(P[12]): left as written: extended axes (E1..)" in err
    assert "(P[3]): left as written: a coordinated move (COORD, line 7)" in err
    assert "(P[4] GP2): left as written: motion group 2" in err
    assert "P[1]" not in err and "P[2])" not in err, err
    # P[1], P[2] corrected; P[3] (COORD), P[4] (UF 3) and its GP2, P[10..12], PR[5] left.
    assert (summary["ok"], summary["left"], summary["unreachable"]) == (2, 7, 0)
    new = out.read_bytes().decode()
    lines = text.splitlines()
    rec = [k + 1 for k, ln in enumerate(lines) if ln.startswith(("P[1]", "P[2]"))]
    _same_outside(text, new, [r + d for r in rec for d in (2, 3, 4)])


def test_krl_comments_and_external_axes(tracker_twin, model_file, run_cli, tmp_path):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(4), 3)
    text = WRITERS["krl"][0](cal, q, _targets(cal, q))
    xp3 = re.search(r"XP3=\{[^}]*E1 0.0", text).group(0)
    text = text.replace(xp3, xp3[:-3] + "350.0")  # a rail at 350 mm
    text = text.replace(
        "DECL E6POS XP3=", ";DECL E6POS XP9={X 1,Y 2,Z 3,A 0,B 0,C 0}\nDECL E6POS XP3="
    )
    res, out = _run(run_cli, model_file, tmp_path, "krl", text, "real.dat")
    summary = _summary(res)
    assert "(XP3): left as written: external axes set" in res.stderr
    assert "XP9" not in res.stderr
    assert (summary["n"], summary["ok"], summary["left"]) == (3, 2, 1)
    _same_outside(text, out.read_text(), [2, 4])
    # Joint aggregates in comments (a commented-out HOME, a note after a move).
    deg = np.degrees(q[0])
    agg = ", ".join(f"A{i + 1} {v:.3f}" for i, v in enumerate(deg))
    src = (
        "DEF real( )\n;FOLD ---- GO HOME ----\n"
        "; PTP {A1 0.000, A2 -90.000, A3 90.000, A4 0.000, A5 0.000, A6 0.000}\n"
        f";ENDFOLD\nPTP {{{agg}}} ; was {{A1 5, A2 5, A3 5, A4 5, A5 5, A6 5}}\n"
        "PTP XHOME\nLIN XP1 C_DIS\nEND\n"
    )
    res, out = _run(run_cli, model_file, tmp_path, "krl", src, "real.src")
    assert res.returncode == 0, res.stderr
    assert "1 joint targets corrected" in res.stderr, res.stderr
    # Targets whose value is elsewhere (the .dat, $config.dat): counted and left.
    for name, line in (("XHOME", 6), ("XP1", 7)):
        assert (
            f"line {line} ({name}): left as written: its value is not in this file"
            in res.stderr
        ), res.stderr
    _same_outside(src, out.read_text(), [5])
    new5 = out.read_text().splitlines()[4]
    assert new5.endswith("; was {A1 5, A2 5, A3 5, A4 5, A5 5, A6 5}")


def test_krl_geometric_operator_operands_are_left(
    tracker_twin, model_file, run_cli, tmp_path
):
    """``LIN XP1:{X 0,..,Z 50,..}`` / ``LIN OFS:XP1`` go to a combination: neither the
    offset aggregate (a displacement) nor XP1 is corrected as a pose to reach (XP1 was,
    and the offset would have been with a joint target before it)."""
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(7), 2)
    dat = WRITERS["krl"][0](cal, q, _targets(cal, q))
    xp1 = re.search(r"DECL E6POS XP1=.*", dat).group(0)
    deg = ", ".join(f"A{i + 1} {v:.3f}" for i, v in enumerate(np.degrees(q[0])))
    src = "\n".join([
        "DEF geo( )", xp1.replace("XP1", "XP9"), xp1, "DECL FRAME OFS",
        "OFS={X 0,Y 0,Z 50,A 0,B 0,C 0}", f"PTP {{{deg}}}", "LIN XP9",
        "LIN XP1:{X 0,Y 0,Z 100,A 0,B 0,C 0} C_DIS", "LIN OFS:XP1", "END", "",
    ])  # fmt: skip
    src = src.replace(
        "DEF geo( )\n", "DEF geo( )\n$BASE=BASE_DATA[1]\n$TOOL=TOOL_DATA[2]\n"
    )
    res, _ = _run(run_cli, model_file, tmp_path, "krl", src, "geo.src")
    err = res.stderr
    assert res.returncode == 0, err
    for name, line in (("XP1", 10), ("OFS", 11), ("POS", 10)):
        why = f"({name}): left as written: an operand of the geometric operator ':' "
        assert why + f"(line {line})" in err, err
    assert "(XP9)" not in err and "1 joint targets corrected" in err, err
    assert "4 Cartesian targets: 1 corrected, 3 left as written" in err, err


def test_rapid_arrays_runtime_targets_do_moves_track_and_comments(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(5), 4)
    text = WRITERS["rapid"][0](cal, q, _targets(cal, q))
    p2 = re.search(r"CONST robtarget p2:=(\[.*\]);", text).group(1)
    p3 = re.search(r"CONST robtarget p3:=\[.*\];", text).group(0)
    text = text.replace(p3, p3.replace("[9E+09,", "[500,", 1))  # a track at 500 mm
    text = text.replace(
        "PROC main()",
        f"  ! Ünïcode: MoveL p0, v100, fine, tool0;\n"
        f"CONST robtarget pArr{{2}}:=[\n  {p2},\n  {p2}];\nVAR robtarget pCur;\nPROC main()",
    )
    text = text.replace(
        "  MoveL p1, v200, fine, tGrip\\WObj:=wTable;",
        "  p2.trans.z := p2.trans.z + 5;\n"
        "  MoveLDO p1, v200, fine, tGrip\\WObj:=wTable, do1, 1;\n"
        "  MoveL pArr{1}, v200, fine, tGrip\\WObj:=wTable;\n"
        "  pCur := CRobT(\\Tool:=tGrip\\WObj:=wTable);\n"
        "  MoveL pCur, v200, fine, tGrip\\WObj:=wTable;",
    )
    res, _ = _run(run_cli, model_file, tmp_path, "rapid", text, "real.mod")
    summary = _summary(res)
    err = res.stderr
    assert "(p3): left as written: external axes set in its extax" in err
    assert "(pArr{1}): left as written: an element of the robtarget array" in err
    assert "(pArr{2}): left as written" in err
    assert "(pCur): left as written: its value is not in this file" in err
    assert "(p0)" not in err and "(p1)" not in err, err
    assert "(p2): left as written: the program assigns it" in err
    assert (summary["n"], summary["ok"], summary["left"]) == (7, 2, 5), err


def test_urscript_commented_moves_are_no_targets(
    tracker_twin, model_file, run_cli, tmp_path
):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(6), 2)
    text = WRITERS["urscript"][0](cal, q, _targets(cal, q))
    text = text.replace(
        "def cart():\n",
        "def cart():\n  # movel(p[0.1, -0.4, 0.2, 0, 3.14, 0], a=1, v=0.1)\n"
        '  textmsg("# not a comment")\n',
    )
    res, _ = _run(run_cli, model_file, tmp_path, "urscript", text, "real.script")
    summary = _summary(res)
    assert (summary["n"], summary["ok"], summary["left"]) == (2, 2, 0), res.stderr


def test_utf16_program_is_refused_with_a_clear_error(model_file, run_cli, tmp_path):
    """A module saved as UTF-16 (RobotStudio, a Windows editor) said "no joint or
    Cartesian target found"; now it names the encoding (exit 2)."""
    text = "MODULE M\n  PROC main()\n    MoveAbsJ [[0,0,0,0,30,0],[9E9,9E9,9E9,9E9,9E9,9E9]],"
    src, out = tmp_path / "u16.mod", tmp_path / "out.mod"
    src.write_bytes(
        (text + " v100, fine, tool0;\n  ENDPROC\nENDMODULE\n").encode("utf-16")
    )
    res = run_cli("compensate", src, "--model", model_file, "--out", out)
    assert res.returncode == 2, res.stderr
    assert "u16.mod: line 1: a NUL byte: the file is UTF-16 encoded" in res.stderr
    assert "Traceback" not in res.stderr and not out.exists()
