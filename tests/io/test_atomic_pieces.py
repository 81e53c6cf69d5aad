"""atomic_write_bytes takes its data in pieces (issue 36: a 1e6-row residuals.csv is never
held whole), with the same all-or-nothing write."""

from __future__ import annotations

import pytest

from kinecal.io import atomic_write_bytes


def test_pieces_are_written_in_turn(tmp_path):
    path = tmp_path / "r.csv"
    atomic_write_bytes(path, (f"{k}\n".encode() for k in range(1000)))
    assert path.read_text() == "".join(f"{k}\n" for k in range(1000))


def test_a_failure_between_pieces_leaves_the_old_file(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("old\n")

    def pieces():
        yield b"new,"
        raise RuntimeError("the data ran out")

    with pytest.raises(RuntimeError, match="ran out"):
        atomic_write_bytes(path, pieces(), force=True)
    assert path.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]  # no temporary left
