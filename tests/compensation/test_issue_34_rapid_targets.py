"""Issue 34: every RAPID move counted. ``Offs(p10, ..)`` and ``RelTool(p10, ..)`` move to
p10 displaced: uses of p10 (its tool and wobj from them); a move to a robtarget of another
module or to a computed one (``CRobT()``) is counted and left with the reason."""

from __future__ import annotations

from kinecal.io._cartesian_programs import read_cartesian

TARGET = "[[400,0,300],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]]"


def test_issue_34_rapid_offs_reltool_and_unknown_targets_counted():
    text = "\n".join(
        [
            "MODULE M",
            f"CONST robtarget p10:={TARGET};",
            f"PERS robtarget p20:={TARGET};",
            f"VAR robtarget p30:={TARGET};",
            "PROC main()",
            "  MoveL Offs(p10, 0, 0, 50), v100, fine, tGrip\\WObj:=wTable;",
            "  MoveL RelTool(p20, 0, 0, -20 \\Rz:=30), v100, z10, tool1;",
            "  MoveJ p30, v100, fine, tool0;",
            "  MoveL Offs(p30, 10, 0, 0), v100, fine, tool2;",
            "  MoveJ CRobT(), v100, fine, tool0;",
            "  MoveL pOther, v100, fine, tool0;",
            "ENDPROC",
            "ENDMODULE",
        ]
    )
    got = {
        p.name: (p.line, p.tool, p.frame, p.why_not.split(":")[0])
        for p in read_cartesian(text, "rapid")
    }
    assert got == {
        "p10": (2, "tGrip", "wTable", ""),
        "p20": (3, "tool1", "wobj0", ""),
        "p30": (4, "", "", "moves use it with different tools or wobjs"),
        "CRobT()": (10, "", "", "a computed target (CRobT())"),
        "pOther": (11, "", "", "pOther"),
    }, got


def test_a_program_joint_far_beyond_the_limits_is_refused(tmp_path):
    """A joint target a turn or more beyond the limits (1e9 deg) is no joint value: it
    was wrapped and 'corrected' into another pose with exit 0; now refused, naming the
    file, line and joint in the file's units. Nearer the limits it is solved and
    reported as 'joint_limit' (exit 4)."""
    import pytest

    from kinecal.errors import DataError
    from kinecal.io import load_model, save_model
    from kinecal.simulation import experiment2
    from kinecal.workflows import compensate_program

    e = experiment2(3)
    from kinecal.identification import calibrate

    cal = load_model(
        save_model(
            tmp_path / "m.yaml",
            calibrate(e.truth.robot, e.train, "kinematic").calibrated,
        )
    )
    ls = tmp_path / "p.ls"
    ls.write_text(
        "/PROG X\n/MN\n   1:J P[1] 100% FINE ;\n/POS\nP[1]{\n   GP1:\n\tUF : 0, UT : 0,\n"
        "\tJ1= 1e9 deg, J2= 0 deg, J3= 0 deg,\n\tJ4= 0 deg, J5= -30 deg, J6= 0 deg\n};\n/END\n"
    )
    with pytest.raises(
        DataError, match=r"p.ls: line 8 \(P\[1\]\): J1 = 1e\+09 deg is not"
    ):
        compensate_program(cal, ls, "fanuc-ls")
    ur = tmp_path / "p.script"
    ur.write_text("def a():\n  movej([0, -1.2, 20.0, 0, 1.0, 0])\nend\n")
    with pytest.raises(DataError, match=r"line 2 \(movej\): J3 = 20 rad is not"):
        compensate_program(cal, ur, "urscript")
