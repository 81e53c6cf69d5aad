"""Audit 7: residuals.csv handed back to ``kinecal report`` as a spreadsheet saves it:
with a byte-order mark (refused: "missing column 'row'", though every CSV kinecal reads
takes one), or with a cell that is no number (named without its column)."""

from __future__ import annotations

import hashlib
import json
import shutil

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal
from tests.helpers import calibrate_args


@pytest.fixture(scope="module")
def cal(tmp_path_factory):
    d = tmp_path_factory.mktemp("audit7_report")
    data = make_point_data(d)
    from kinecal.cli import main

    assert main(calibrate_args(data["train"], "fanuc-lrmate200id", d / "cal")) == 0
    return d / "cal"


def _saved_as(cal, tmp_path, text):
    """A copy of the folder whose residuals.csv is ``text`` (its manifest updated, as
    if that run had written it)."""
    d = tmp_path / "cal"
    shutil.copytree(cal, d)
    (d / "residuals.csv").write_bytes(text.encode("utf-8"))
    man = json.loads((d / "manifest.json").read_text())
    man["outputs"]["residuals.csv"] = hashlib.sha256(text.encode()).hexdigest()
    (d / "manifest.json").write_text(json.dumps(man))
    return d


def test_residuals_with_a_byte_order_mark(capsys, tmp_path, cal):
    text = (cal / "residuals.csv").read_text()
    d = _saved_as(cal, tmp_path, "\ufeff" + text.replace("\n", "\r\n"))
    res = run_kinecal(capsys, "report", d, "--out", tmp_path / "r.html")
    assert res.code == 0, str(res)
    assert (tmp_path / "r.html").is_file()


def test_a_cell_that_is_no_number_names_its_column(capsys, tmp_path, cal):
    lines = (cal / "residuals.csv").read_text().splitlines()
    cells = lines[1].split(",")
    cells[2] = "abc"
    d = _saved_as(cal, tmp_path, "\n".join([lines[0], ",".join(cells), *lines[2:]]))
    res = run_kinecal(capsys, "report", d, "--out", tmp_path / "r.html")
    col = lines[0].split(",")[2]
    failed_with(
        res, "residuals.csv", "line 2: 'abc' is not a number", f"(column '{col}')"
    )
