"""Issue 34: every FANUC target counted, the second point of a circular move too: ``C``
moves to PR[n] (via) and, on the continuation line, PR[m] (end)."""

from __future__ import annotations

from kinecal.io._cartesian_programs import read_cartesian

LS = "\n".join(
    [
        "/PROG  ARC",
        "/MN",
        "   1:  UFRAME_NUM=1 ;",
        "   2:  UTOOL_NUM=1 ;",
        "   3:C PR[2:via]    ",
        "    :  PR[3:end] 100mm/sec FINE    ;",
        "   4:L PR[4] 100mm/sec FINE    ;",
        "/POS",
        "/END",
        "",
    ]
)


def test_issue_34_circular_second_point_is_counted():
    got = [(p.name, p.line) for p in read_cartesian(LS, "fanuc-ls")]
    assert got == [("PR[2:via]", 5), ("PR[3:end]", 6), ("PR[4]", 7)], got
