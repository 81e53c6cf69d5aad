"""Audit 9: robot programs handed to compensate. A KRL axis aggregate with a value that
is no number, a decimal comma, an axis twice or a declaration without A6 was taken for
a partial aggregate: left unread and unreported (or ``A1 15,5`` read as A1 = 15), the
program written back with exit 0. A FANUC ``J1 = 10 mm`` on a revolute joint was read as
10 deg. Reading a program of many targets was quadratic in its length."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.io import program_joints, read_program
from kinecal.robot import load_robot

DATA = Path(__file__).parents[1] / "data" / "programs"
ROBOT = load_robot("fanuc-lrmate200id")


def _dat(tmp_path: Path, old: str, new: str) -> Path:
    text = (DATA / "pick_demo.dat").read_text()
    assert old in text
    p = tmp_path / "damaged.dat"
    p.write_text(text.replace(old, new))
    return p


@pytest.mark.parametrize(
    "old, new, match",
    [
        ("A1 15.5", "A1 abc", r"line 7: A1 'abc' is not a number"),
        ("A1 15.5", "A1 15,5", r"line 7: '5' in the axis aggregate .* decimal comma"),
        ("A6 45.0,", "A5 45.0,", r"line 7: A5 is given twice"),
        ("A6 45.0,", "", r"line 7: the declared axis aggregate lacks A6"),
        ("A1 15.5,A2 -80.25", "A2 -80.25,A1 15.5", r"line 7: .*in order"),
    ],
)
def test_damaged_krl_axis_aggregates_are_named(tmp_path, old, new, match):
    p = _dat(tmp_path, old, new)
    with pytest.raises(DataError, match=f"{p}: {match}"):
        read_program(p)


def test_sound_krl_aggregates_still_read(tmp_path):
    # a partial aggregate in a motion (the robot's other axes), a frame, FDAT / PDAT
    p = tmp_path / "moves.src"
    p.write_text(
        "DEF moves()\n"
        "  DECL FDAT FP1={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE}\n"
        "  DECL PDAT PP1={VEL 100,ACC 100,APO_DIST 100}\n"
        "  PTP {A1 10, A2 -80, A3 90, A4 0, A5 30, A6 0, E1 5}\n"
        "  PTP {A1 20}\n"
        "  LIN {X 800, Y 0, Z 600, A 0, B 90, C 0}\n"
        "END\n"
    )
    prog = read_program(p)
    assert [pt.line for pt in prog.points] == [4]
    assert prog.points[0].values[:6] == (10.0, -80.0, 90.0, 0.0, 30.0, 0.0)
    assert read_program(DATA / "pick_demo.dat").points[1].values[0] == 15.5


def test_fanuc_joint_value_in_the_other_unit(tmp_path):
    text = (DATA / "pick_demo.ls").read_text()
    p = tmp_path / "mm.ls"
    p.write_text(text.replace("J1=    10.000 deg", "J1=    10.000  mm"))
    prog = read_program(p)
    with pytest.raises(DataError, match=rf"{p}: line 23: P\[1\] J1 = 10 mm; J1 .* "
                       r"is revolute: expected deg"):  # fmt: skip
        program_joints(prog, ROBOT)
    assert program_joints(read_program(DATA / "pick_demo.ls"), ROBOT).shape == (3, 6)


def test_empty_and_cr_only_programs_say_so(tmp_path):
    for name, raw, match in (
        ("empty.ls", b" \n\n", r"empty.ls: the program is empty; expected a fanuc-ls"),
        (
            "mac.ls",
            (DATA / "pick_demo.ls").read_bytes().replace(b"\n", b"\r"),
            r"mac.ls: its lines end in CR only",  # was: line 1: ends without /END
        ),
    ):
        (tmp_path / name).write_bytes(raw)
        with pytest.raises(DataError, match=match):
            read_program(tmp_path / name)


def test_a_program_beyond_the_size_bound(tmp_path, monkeypatch):
    from kinecal.errors import CalibError

    p = tmp_path / "big.script"
    p.write_text("def p():\n" + "  # comment\n" * 200_000 + "end\n")  # 2.4 MB
    monkeypatch.setattr("kinecal.io._programs.MAX_PROGRAM_BYTES", 1 << 20)
    with pytest.raises(CalibError, match=r"big.script: 2.3 MB; expected a urscript"):
        read_program(p)


@pytest.mark.slow
def test_many_targets_read_in_linear_time(tmp_path):
    move = "  movej([0.1, -1.3, 1.5, -1.7, -1.5, 0.0], a=1, v=1)\n"

    def took(n: int) -> float:
        p = tmp_path / f"many{n}.script"
        p.write_text("def p():\n" + move * n + "end\n")
        best = np.inf
        for _ in range(2):
            t0 = time.perf_counter()
            prog = read_program(p)
            best = min(best, time.perf_counter() - t0)
        assert len(prog.points) == n and prog.points[-1].line == n + 1
        return best

    # 4x the moves: 4x the time (the line ends counted per target: up to 16x; 20 000
    # moves took 16 s under a profiler)
    ratio = took(12000) / took(3000)
    assert ratio < 6.5, ratio  # linear 4.3, quadratic 8.6 here


@pytest.mark.parametrize(
    "name, text, needle",
    [
        (
            "d2r.script",
            "def p():\n  movej([d2r(10), d2r(-80), d2r(90), 0, 0, 0], a=1, v=1)\n"
            "  movej([0.1, -1.3, 1.5, -1.7, -1.5, 0.0], a=1, v=1)\nend\n",
            "line 2 (movej [d2r(10), d2r(-80), d2r(90), 0, 0, 0])",
        ),
        (
            "twice.script",
            "def p():\n  q1 = [0.1, -1.3, 1.5, -1.7, -1.5, 0.0]\n"
            "  q1 = [0.2, -1.3, 1.5, -1.7, -1.5, 0.0]\n  movej(q1, a=1, v=1)\n"
            "  movej([0.1, -1.3, 1.5, -1.7, -1.5, 0.0], a=1, v=1)\nend\n",
            "line 2 (q1, assigned 2 times)",
        ),
        (
            "expr.mod",
            (DATA / "pick_demo.mod")
            .read_text()
            .replace("[[12.5,-20.25,35,0.5,45,-90]", "[[12.5,-20.25,35,0.5,45,-90+5]"),
            "line 4 (jAbove [12.5,-20.25,35,0.5,45,-90+5])",
        ),
        (
            "undefined.mod",
            (DATA / "pick_demo.mod")
            .read_text()
            .replace("MoveAbsJ jHome\\NoEOffs", "MoveAbsJ jPark\\NoEOffs"),
            "line 7 (MoveAbsJ jPark, not defined in this module)",
        ),
    ],
)
def test_joint_targets_that_are_expressions_are_named(tmp_path, name, text, needle):
    """They were written back uncorrected without a word (every target 'compensated')."""
    from kinecal.io._checks import DataWarning

    p = tmp_path / name
    p.write_text(text)
    with pytest.warns(DataWarning, match="left as written, not numbers") as got:
        prog = read_program(p)
    assert needle in str(got[0].message), str(got[0].message)
    assert prog.points  # the others are read


def test_programs_of_numbers_warn_nothing(recwarn):
    for name in ("pick_demo.script", "pick_demo.mod", "pick_demo.ls", "pick_demo.dat"):
        read_program(DATA / name)
    assert not [w for w in recwarn if "left as written" in str(w.message)]
