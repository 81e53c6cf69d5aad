"""Audit 8: files saved on Windows and handed back: a robot YAML with a byte-order mark
(Notepad) was refused as "a CSV table (first line '\\ufeff# ...')"; UTF-16 files were
called CSV tables or "not a text file", and a Latin-1 byte named no line."""

from __future__ import annotations

import pytest
import yaml

from kinecal.errors import CalibError
from kinecal.io import load_model, read_table
from kinecal.robot import dump_robot, load_robot

ROBOT = "# my arm, as exported\n" + yaml.dump(
    dump_robot(load_robot("fanuc-lrmate200id"))
)


def test_a_robot_file_with_a_bom_and_crlf_loads(tmp_path):
    f = tmp_path / "robot.yaml"
    f.write_bytes(b"\xef\xbb\xbf" + ROBOT.replace("\n", "\r\n").encode())
    assert load_robot(f).n_joints == 6


@pytest.mark.parametrize(
    ("encoding", "match"),
    [
        ("utf-16", r"robot\.yaml: UTF-16 encoded \(or binary\); expected a robot YAML"),
        ("latin-1", r"robot\.yaml: line 1: byte 0xe9 is not UTF-8 \(a Latin-1"),
    ],
)
def test_a_robot_file_in_another_encoding(tmp_path, encoding, match):
    f = tmp_path / "robot.yaml"
    f.write_text(ROBOT.replace("my arm", "mon bras modifié"), encoding=encoding)
    with pytest.raises(CalibError, match=match):
        load_robot(f)


def test_a_model_file_in_utf16(tmp_path):
    f = tmp_path / "model.yaml"
    f.write_text("kinecal_model: 1\n", encoding="utf-16")
    with pytest.raises(
        CalibError, match=r"model\.yaml: UTF-16 encoded .*a model\.yaml"
    ):
        load_model(f)


@pytest.mark.parametrize(
    ("encoding", "match"),
    [
        ("utf-16", r"d\.csv: UTF-16 encoded \(or binary\): not a text \(UTF-8\) CSV"),
        ("latin-1", r"d\.csv: line 2: byte 0xb0 is not UTF-8"),
    ],
)
def test_a_csv_in_another_encoding_names_its_line(tmp_path, encoding, match):
    f = tmp_path / "d.csv"
    f.write_text("j1_deg,x_mm\n# at 20 °C\n1,2\n", encoding=encoding)
    with pytest.raises(CalibError, match=match):
        read_table(f)


def test_a_quoted_decimal_comma_is_named(tmp_path):
    """'"1,5"' between commas (a spreadsheet's export with a decimal comma): said so."""
    f = tmp_path / "d.csv"
    f.write_text('j1_deg,x_mm\n"1,5","2,25"\n')
    with pytest.raises(CalibError, match=r"line 2, column 'j1_deg': expected a number; "
                       r"got '1,5' \(a decimal comma: write 1\.5, or ';' between"):  # fmt: skip
        read_table(f).numbers("j1_deg")
