"""Program files (issue 23, item 4): joint targets read and written back in place, the
rest of the text kept byte for byte. The sample programs in tests/data/programs were
written for these tests (see its README)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.io._programs import (
    program_bytes,
    program_joints,
    read_program,
    write_program,
    written_joints,
)
from kinecal.robot import load_robot

DATA = Path(__file__).parents[1] / "data" / "programs"
SAMPLES = {
    "pick_demo.ls": ("fanuc-ls", 3, 1),
    "pick_demo.script": ("urscript", 4, 1),  # q_rest = [..]; movej(q_rest): a target
    "pick_demo.mod": ("rapid", 3, 1),
    "pick_demo.dat": ("krl", 2, 1),
}
ROBOT = load_robot("fanuc-lrmate200id")


def _outside(text: str, spans) -> str:
    """The text with every joint value cut out."""
    out, last = [], 0
    for a, b in sorted(spans):
        out.append(text[last:a])
        last = b
    return "".join(out) + text[last:]


def _spans(prog):
    return [s for pt in prog.points for s in pt.spans[: ROBOT.n_joints]]


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_formats_read_the_joint_targets(name):
    fmt, n_points, n_cartesian = SAMPLES[name]
    prog = read_program(DATA / name)
    assert prog.format == fmt
    assert len(prog.points) == n_points and prog.skipped == n_cartesian
    q = program_joints(prog, ROBOT)
    assert q.shape == (n_points, 6) and np.isfinite(q).all()
    if fmt == "urscript":
        np.testing.assert_allclose(
            q[0], [0.174533, -1.396263, 1.570796, -1.745329, -1.570796, 0.0]
        )
    else:
        deg = {"fanuc-ls": [10, 20, -10, 0, -65.5, 120.25], "rapid": [0, 0, 0, 0, 30, 0],
               "krl": [0, -90, 90, 0, 0, 0]}[fmt]  # fmt: skip
        np.testing.assert_allclose(np.degrees(q[0]), deg, atol=1e-12)


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_round_trip_unchanged_is_byte_for_byte(name):
    prog = read_program(DATA / name)
    text = write_program(prog, program_joints(prog, ROBOT), ROBOT)
    assert program_bytes(text) == (DATA / name).read_bytes()


@pytest.mark.parametrize("name", sorted(SAMPLES))
@pytest.mark.parametrize("decimals", [None, 6])
def test_round_trip_corrected_keeps_everything_else(name, decimals, rng):
    prog = read_program(DATA / name)
    q = program_joints(prog, ROBOT)
    q_new = q + np.radians(rng.uniform(-0.5, 0.5, q.shape))
    text = write_program(prog, q_new, ROBOT, decimals=decimals)
    again = read_program(DATA / name)  # the original, for its spans
    new = type(prog)(prog.path, prog.format, text, (), 0)
    reread = written_joints(prog, text, ROBOT)
    dec = (
        decimals
        if decimals is not None
        else {"fanuc-ls": 3, "urscript": 8}.get(prog.format, 4)
    )
    unit = 1.0 if prog.format == "urscript" else np.pi / 180.0
    assert np.abs(reread - q_new).max() <= 0.5 * 10.0**-dec * unit * (1 + 1e-9)
    # Outside the joint values nothing moved (external axes, Cartesian targets, comments).
    from kinecal.io._programs import _READERS

    pts, _ = _READERS[prog.format](text)
    new_spans = [s for pt in pts for s in pt.spans[:6]]
    assert _outside(text, new_spans) == _outside(again.text, _spans(again))
    assert new.text.count("\n") == prog.text.count("\n")
    if (
        prog.format == "fanuc-ls" and decimals is None
    ):  # columns kept: values end in place
        assert [b for _, b in new_spans] == [b for _, b in _spans(prog)]
        assert "\r\n" in text and "\n" not in text.replace("\r\n", "")


def test_rows_kept_and_bytes_that_are_not_utf8(tmp_path, rng):
    raw = (
        (DATA / "pick_demo.ls")
        .read_bytes()
        .replace(b"kinecal test", b"kinecal \xe9t\xe9")
    )
    path = tmp_path / "latin1.ls"
    path.write_bytes(raw)
    prog = read_program(path)
    q = program_joints(prog, ROBOT)
    keep = np.array([False, True, False])
    text = write_program(prog, q + 0.01, ROBOT, keep=keep)
    assert b"kinecal \xe9t\xe9" in program_bytes(text)
    reread = written_joints(prog, text, ROBOT)
    np.testing.assert_allclose(reread[1], q[1], atol=0)
    assert np.abs(reread[[0, 2]] - q[[0, 2]] - 0.01).max() < np.radians(6e-4)


def test_bad_programs_name_file_and_line(tmp_path):
    p = tmp_path / "empty.script"
    p.write_text("def f():\n  sleep(1.0)\nend\n")  # a pose alone is a target now
    with pytest.raises(
        DataError,
        match=r"empty.script: no joint or Cartesian target found \(urscript\)",
    ):
        read_program(p)
    p = tmp_path / "five.script"
    p.write_text("def f():\n  movej([0.1, 0.2, 0.3, 0.4, 0.5], a=1)\nend\n")
    with pytest.raises(
        DataError, match=r"five.script: line 2: movej has 5 joint values; "
    ):
        program_joints(read_program(p), ROBOT)
    shutil.copy(DATA / "pick_demo.ls", tmp_path / "x.ls")
    text = (tmp_path / "x.ls").read_text().replace("J2=    20.000", "J3=    20.000")
    (tmp_path / "x.ls").write_text(text)
    with pytest.raises(
        DataError, match=r"x.ls: line 2\d: P\[1\] lists joints \[1, 3, 3"
    ):
        read_program(tmp_path / "x.ls")
    with pytest.raises(DataError, match="unknown program format 'gcode'"):
        read_program(DATA / "pick_demo.ls", "gcode")
    with pytest.raises(DataError, match="cannot read program"):
        read_program(tmp_path / "missing.mod")


def test_fanuc_negative_zero_and_wide_values():
    prog = read_program(DATA / "pick_demo.ls")
    q = program_joints(prog, ROBOT)
    q[0, 3] = np.radians(-1234.5678)  # wider than the column: a blank stays after '='
    text = write_program(prog, q, ROBOT)
    assert "J4= -1234.568 deg" in text
    assert re.search(r"J4=\s+-\.000 deg", (DATA / "pick_demo.ls").read_text())
