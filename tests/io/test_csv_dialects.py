"""CSV files as spreadsheets and trackers write them: semicolons with decimal commas,
tabs, a byte-order mark, Windows line ends, comments and blank lines all read the same
numbers as the plain comma-separated file."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.io import read_measurements
from kinecal.robot import load_robot

ROBOT = load_robot("fanuc-lrmate200id")
PLAIN = """j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,x_mm,y_mm,z_mm,marker
10.5,-20.25,5,0,-60,30,812.125,-120.5,300.75,a
-30,15.5,-10,45.25,-30,90,700.5,-250.25,410,b
0,0,0,0,-90,0,650,0.5,280.125,a
20,-5,15,-45,-45,-90,720,180.5,350,b
"""


def _variants(text: str) -> dict[str, bytes]:
    lines = text.splitlines()
    return {
        "semicolon, decimal comma": "\n".join(
            s.replace(",", ";").replace(".", ",") for s in lines
        ).encode(),
        "tab": "\n".join(s.replace(",", "\t") for s in lines).encode(),
        "tab, decimal comma": "\n".join(
            s.replace(",", "\t").replace(".", ",") for s in lines
        ).encode(),
        "BOM and CRLF": b"\xef\xbb\xbf" + text.replace("\n", "\r\n").encode(),
        "comments and blanks": ("# exported\n\n" + text + "\n\n").encode(),
    }


@pytest.mark.parametrize("kind", list(_variants(PLAIN)))
def test_dialects_read_the_same_numbers(tmp_path, kind):
    plain = tmp_path / "plain.csv"
    plain.write_text(PLAIN)
    ref = read_measurements(plain, ROBOT)
    f = tmp_path / "other.csv"
    f.write_bytes(_variants(PLAIN)[kind])
    got = read_measurements(f, ROBOT)
    np.testing.assert_array_equal(got.q_ctrl, ref.q_ctrl)
    np.testing.assert_array_equal(got.p, ref.p)
    assert got.marker_labels == ref.marker_labels
    shift = 2 if kind == "comments and blanks" else 0  # rows are file lines
    np.testing.assert_array_equal(got.rows, ref.rows + shift)


def test_a_semicolon_file_names_its_bad_cell(tmp_path):
    f = tmp_path / "semi.csv"
    bad = PLAIN.replace("812.125", "812.1x5")
    f.write_text("\n".join(s.replace(",", ";") for s in bad.splitlines()))
    with pytest.raises(DataError, match=r"line 2, column 'x_mm': expected a number"):
        read_measurements(f, ROBOT)
