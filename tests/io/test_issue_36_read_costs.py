"""Issue 36: the data checks of a large file cost little where their answer is clear
early, and say the same as the full check where it is not."""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from kinecal.identification import Measurements
from kinecal.io import _checks, data_diagnostics
from kinecal.robot import RobotDescription, load_robot

FANUC = load_robot("fanuc-lrmate200id")


def _counted_fk(monkeypatch) -> list[int]:
    rows: list[int] = []
    fk = RobotDescription.fk_flange

    def counted(self, q, *a, **k):
        rows.append(int(np.shape(q)[0]))
        return fk(self, q, *a, **k)

    monkeypatch.setattr(RobotDescription, "fk_flange", counted)
    return rows


def _poses(rng, n: int, spread_deg: float) -> Measurements:
    q = np.radians([0.0, 10.0, -20.0, 0.0, -60.0, 0.0]) + np.radians(
        spread_deg
    ) * rng.uniform(-1, 1, (n, 6))
    return Measurements("point", q, FANUC.fk_flange(q)[:, :3, 3])


def test_issue_36_excitation_turns_few_rows_when_the_tool_turns(monkeypatch, rng):
    """2000 well spread poses: the orientation check's forward kinematics on a few
    rows (it was all 2000 + 1: 2.5 ms of a 2000-pose calibrate)."""
    meas = _poses(rng, 2000, 60.0)
    rows = _counted_fk(monkeypatch)
    found = _checks.excitation(meas, FANUC)
    assert found == []
    assert sum(rows) <= _checks._FEW_ROWS + 1


def test_issue_36_a_tool_that_hardly_turns_is_said_with_the_spread_of_all_rows(
    monkeypatch, rng
):
    """Below the limit, the few rows are only a first look: the message gives the
    spread of the whole sample, as before."""
    meas = _poses(rng, 3000, 0.8)
    full = _checks._orientation_spread_deg(meas, FANUC)
    rows = _counted_fk(monkeypatch)
    found = [d for d in data_diagnostics(meas, FANUC) if "orientation" in d.message]
    assert len(found) == 1 and f"within {full:.3g} deg" in found[0].message
    assert sum(rows) > 2000  # the few rows, then the whole sample


class _CountedText(str):
    """A text that records the length of every text it splits into lines whole."""

    split: ClassVar[list[int]] = []

    def splitlines(self, *a, **k):
        _CountedText.split.append(len(self))
        return super().splitlines(*a, **k)


def test_issue_36_the_header_is_found_without_splitting_the_whole_file():
    from kinecal.io._table import _comma_separated

    body = "".join(f"{i};{i / 7:.6f}\n" for i in range(20000))
    _CountedText.split = []
    text = _CountedText("# a comment\n\nj1_deg;x_mm\n" + body)
    assert _comma_separated(text) == text.replace(",", ".").replace(";", ",")
    assert _CountedText.split == []  # only its first part was split


def test_issue_36_comment_and_blank_lines_are_found_as_before(tmp_path):
    """Whether a file has comment or blank lines (dropped, each kept line's number
    remembered) is decided on the lines' first characters, without a loop over the
    lines: a line of blank cells is dropped for every white space character."""
    from kinecal.io import read_table

    breaks = {
        "\n",
        "\r",
        "\x0b",
        "\x0c",
        "\x1c",
        "\x1d",
        "\x1e",
        "\x85",
        "\u2028",
        "\u2029",
    }
    spaces = [c for c in map(chr, range(0x3100)) if c.isspace() and c not in breaks]
    assert len(spaces) > 15
    for i, c in enumerate(["", *spaces]):
        for blank in (f"{c},{c}", f"{c}# note", f",{c}"):
            f = tmp_path / f"t{i}.csv"
            f.write_text(f"a,b\n1,2\n{blank}\n4,5\n", encoding="utf-8")
            assert read_table(f).lines.tolist() == [2, 4], (hex(ord(c or " ")), blank)
