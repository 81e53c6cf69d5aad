"""A column of set-ups under another name (``session``, ``station``, ``set_id``, ...):
several tracker stations were calibrated with one user frame, unsaid (the column was an
extra one, ignored). With several values and no ``set`` column it is now a finding of
the data (a warning: such a column may be meant for ``--cv-groups``)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from kinecal.io import read_data
from kinecal.robot import load_robot
from tests.cli_contract import make_point_data

ROBOT = load_robot("fanuc-lrmate200id")


@pytest.fixture(scope="module")
def train(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return make_point_data(tmp_path_factory.mktemp("setlike"))["train"]


def _with(src: Path, dst: Path, name: str, value) -> Path:
    lines = src.read_text().splitlines()
    rows = [f"{ln},{value(k)}" for k, ln in enumerate(lines[1:])]
    dst.write_text("\n".join([f"{lines[0]},{name}", *rows]) + "\n")
    return dst


@pytest.mark.parametrize("name", ["session", "Station", "set_id", "setup"])
def test_a_column_of_several_set_ups_under_another_name_is_named(train, tmp_path, name):
    f = _with(train, tmp_path / "d.csv", name, lambda k: "s1" if k < 20 else "s2")
    _, found = read_data(f, ROBOT)
    (d,) = [d for d in found if d.code == "set_like_column"]
    assert re.search(
        rf"column '{name}' has 2 values .*one user frame.*'set'", d.message
    )
    assert d.severity == "warning"


def test_one_value_throughout_or_beside_a_set_column_is_a_label(train, tmp_path):
    one = _with(train, tmp_path / "one.csv", "session", lambda k: "2026-12-04")
    assert "set_like_column" not in [d.code for d in read_data(one, ROBOT)[1]]
    both = _with(train, tmp_path / "s.csv", "set", lambda k: "A" if k < 20 else "B")
    both = _with(both, tmp_path / "both.csv", "station", lambda k: k % 3)
    m, found = read_data(both, ROBOT)
    assert m.set_labels == ("A", "B")
    assert "set_like_column" not in [d.code for d in found]
