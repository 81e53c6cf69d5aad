"""Audit 7: robot programs handed to ``kinecal compensate`` with damage the readers
passed over: a joint value ``nan`` (the target was skipped as an expression and written
back uncorrected, unreported, exit 0), a FANUC joint value in radians or without a unit
(named as "joints not in order"), a FANUC position defined twice (both corrected) or
moved to but not defined. Each is refused naming the file, the line and what was
expected."""

from __future__ import annotations

from pathlib import Path

import pytest

from kinecal.errors import DataError
from kinecal.io._programs import read_program
from tests.cli_contract import failed_with, make_point_data, run_kinecal

DATA = Path(__file__).parents[1] / "data" / "programs"
LS = (DATA / "pick_demo.ls").read_text()
SCRIPT = (DATA / "pick_demo.script").read_text()
MOD = (DATA / "pick_demo.mod").read_text()
SRC = "DEF pick()\n PTP {A1 10, A2 -80, A3 90, A4 0, A5 30, A6 0}\nEND\n"


def _program(tmp_path: Path, name: str, text: str) -> Path:
    f = tmp_path / name
    f.write_text(text)
    return f


CASES = [
    # (file, text, needles)
    (
        "a.script",
        SCRIPT.replace("[-0.4, -1.2, 1.4", "[nan, -1.2, 1.4"),
        ["line 6", "'nan'", "expected a finite number"],
    ),
    (
        "a.mod",
        MOD.replace("[[12.5,-20.25", "[[NaN,-20.25"),
        ["line 4", "'NaN'", "expected a finite number"],
    ),
    (
        "a.src",
        SRC.replace("A2 -80", "A2 -inf"),
        ["line 2", "'-inf'", "expected a finite number"],
    ),
    (
        "a.ls",
        LS.replace("J5=   -65.500 deg", "J5=   nan deg"),
        ["line 24", "'nan'", "finite number"],
    ),
    (
        "a.ls",
        LS.replace("J5=   -65.500 deg", "J5=   -65.500 rad"),
        ["line 24", "P[1] J5 = -65.500 rad", "expected deg (mm for a linear axis)"],
    ),
    (
        "a.ls",
        LS.replace("J5=   -65.500 deg", "J5=   -65.500"),
        ["line 24", "P[1] J5 = -65.500 without a unit", "expected deg"],
    ),
    (
        "a.ls",
        LS.replace("P[4]{", "P[1]{"),
        ["line 41", "P[1] is defined twice in /POS (first on line 20)"],
    ),
    (
        "a.ls",
        LS.replace("6:L P[4] 200mm/sec", "6:L P[9] 200mm/sec"),
        ["line 18", "a move to P[9]", "P[1], P[2], P[3], P[4]"],
    ),
]


@pytest.mark.parametrize("name, text, needles", CASES)
def test_damaged_targets_are_refused(tmp_path, name, text, needles):
    f = _program(tmp_path, name, text)
    with pytest.raises(DataError) as err:
        read_program(f)
    for n in [str(f), *needles]:
        assert n in str(err.value), str(err.value)


@pytest.mark.parametrize(
    "name, text",
    [
        ("a.ls", LS),
        ("a.script", SCRIPT),
        ("a.mod", MOD),
        ("a.src", SRC),
        # a variable or an expression in a list is not a damaged value
        ("b.script", SCRIPT + "  movej([infeed, -1.2, 1.4, -1.8, -1.5, nano])\n"),
        ("c.script", SCRIPT.replace("a=1.4, v=1.05)", "a=1.4, v=inf)", 1)),
    ],
)
def test_sound_programs_still_read(tmp_path, name, text):
    assert read_program(_program(tmp_path, name, text)).points


def test_compensate_refuses_a_nan_target_and_writes_nothing(capsys, tmp_path):
    """It wrote the program back with the target uncorrected (exit 0)."""
    data = make_point_data(tmp_path)
    f = _program(tmp_path, "a.mod", MOD.replace("[[12.5,-20.25", "[[nan,-20.25"))
    out = tmp_path / "out.mod"
    res = run_kinecal(capsys, "compensate", f, "--model", data["model"], "--out", out)
    failed_with(res, str(f), "line 4", "'nan'")
    assert not out.exists()
