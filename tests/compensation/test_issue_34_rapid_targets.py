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
