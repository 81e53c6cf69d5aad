"""Issue 34: every URScript move counted. A move to a computed target (``pose_add(..)``,
``get_target_tcp_pose()``) or to a variable the script never assigns a pose is counted and
left with the reason (they were not counted); a move to a joint-list variable is a joint
target at its assignment, not a Cartesian one."""

from __future__ import annotations

from kinecal.io import read_program
from kinecal.io._cartesian_programs import read_cartesian

SCRIPT = "\n".join(
    [
        "def prog():",
        "  q_home = [0.0, -1.57, 1.2, -1.57, -1.57, 0.0]",
        "  movej(q_home, a=1.0, v=0.5)",
        "  movej(get_inverse_kin(p[0.3, 0.2, 0.3, 0, 3.1, 0]), a=1.4)",
        "  x = pose_add(p[0.3, 0.2, 0.3, 0, 3.1, 0], p[0, 0, 0.1, 0, 0, 0])",
        "  movel(x)",
        "  movel(get_target_tcp_pose())",
        "  movel(unknown_pose)",
        "  movel(pose_trans(Plane_1, unknown2))",
        "  w = p[0.4, 0.1, 0.3, 0, 3.1, 0]",
        "  movel(w)",
        "end",
        "",
    ]
)


def test_issue_34_every_urscript_move_counted(tmp_path):
    got = [
        (p.line, bool(p.values), p.why_not) for p in read_cartesian(SCRIPT, "urscript")
    ]
    assert got == [
        (4, True, ""),
        (6, False, "x: not assigned a pose p[..] in the script"),
        (7, False, "a computed target (get_target_tcp_pose())"),
        (8, False, "unknown_pose: not assigned a pose p[..] in the script"),
        (9, False, "unknown2: not assigned a pose p[..] in the script"),
        (10, True, ""),
    ], got
    f = tmp_path / "p.script"
    f.write_text(SCRIPT)
    assert [(p.name, p.line) for p in read_program(f).points] == [("q_home", 2)]
