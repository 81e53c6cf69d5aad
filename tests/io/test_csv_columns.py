"""Issue 26, point 3: CSV files read and written column-wise give exactly what the
row-by-row code gave (values, messages with file, line, column, value; bytes written)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.geometry import matrix_to_quat_wxyz, rpy_to_matrix
from kinecal.identification import Measurements
from kinecal.io import Column, csv_text, measurements_to_csv, read_table, table_csv
from kinecal.io._csv_format import _fixed
from kinecal.robot import load_robot

ROBOT = load_robot("fanuc-lrmate200id")


def _reference_table(text: str) -> tuple[list[str], list[list[str]], list[int]]:
    """The row-by-row reader kinecal had before issue 26 (csv module)."""
    header, rows, lines = None, [], []
    for lineno, row in enumerate(csv.reader(text.splitlines()), start=1):
        if (
            not row
            or all(not c.strip() for c in row)
            or row[0].lstrip().startswith("#")
        ):
            continue
        if header is None:
            header = [c.strip() for c in row]
            continue
        rows.append(row)
        lines.append(lineno)
    assert header is not None
    return header, rows, lines


@pytest.mark.parametrize(
    "text",
    [
        "a,b,c\n1,2,3\n4,5,6\n",
        "# comment\na,b,c\n\n1,2,3\n  # indented comment\n,,\n4,5,6\n",
        "a,b,c\r\n1,2,3\r\n\r\n4,5,6\r\n",
        "\ufeffa, b ,c\n 1 ,2,3\n4,5,  6\n",
        'a,b,c\n"1",2,3\n4,"x,y",6\n',
        "a,b,c\n1,2,3\x0c4,5,6\n",
        "a,b,c\n1,#2,3\n#4,5,6\n",
        "a,b,c\n1,2,3",
    ],
)
def test_issue_26_reader_matches_the_row_by_row_reader(tmp_path, text):
    f = tmp_path / "t.csv"
    f.write_text(text, encoding="utf-8")
    t = read_table(f)
    header, rows, lines = _reference_table(text.lstrip("\ufeff"))
    assert t.header == header
    assert t.rows == rows
    assert list(t.lines) == lines
    for k, name in enumerate(header):
        assert t.column(name) == [r[k] for r in rows]


def test_issue_26_numbers_parse_like_python_float(tmp_path):
    f = tmp_path / "n.csv"
    f.write_text("a,b,c\n 1.5 ,1_000,+.5\n-0,1e-3, 7\n")
    t = read_table(f)
    np.testing.assert_array_equal(t.numbers("a"), [1.5, -0.0])
    np.testing.assert_array_equal(t.numbers("b"), [1000.0, 1e-3])  # Python's float
    np.testing.assert_array_equal(t.numbers("c"), [0.5, 7.0])


@pytest.mark.parametrize(
    ("cell", "message"),
    [
        ("abc", "line 4, column 'y': expected a number; got 'abc'"),
        ("", "line 4, column 'y': expected a number; got ''"),
        ("nan", "line 4, column 'y': expected a finite number; got 'nan'"),
        (" -inf", "line 4, column 'y': expected a finite number; got '-inf'"),
    ],
)
def test_issue_26_a_bad_value_is_named_exactly(tmp_path, cell, message):
    f = tmp_path / "bad.csv"
    f.write_text(f"x,y,label\n1,2,a\n# c\n3,{cell},b\n5,6,c\n")
    t = read_table(f)
    np.testing.assert_array_equal(t.numbers("x"), [1.0, 3.0, 5.0])
    with pytest.raises(DataError) as info:
        t.numbers("y")
    assert str(info.value) == f"{f}: {message}."


def test_issue_26_wrong_number_of_values_names_the_line(tmp_path):
    f = tmp_path / "ragged.csv"
    f.write_text("x,y,z\n1,2,3\n\n4,5\n6,7,8\n")
    with pytest.raises(
        DataError, match=r"ragged.csv: line 4: 2 values for 3 columns\."
    ):
        read_table(f)


def test_issue_26_fixed_point_columns_equal_printf(rng):
    ties = np.array([0.5, 1.5, 2.5, -2.5, 0.125, 0.375, 1e15, -1e15, 1e20, 9.999999995])
    odd = np.array([0.0, -0.0, 1e-9, -1e-9, 5e-9, -5e-9, np.nan, np.inf, -np.inf])
    near = np.round(rng.uniform(-100, 100, 5000), 8) + 5e-9  # near a rounding tie
    values = np.concatenate(
        [rng.uniform(-1e3, 1e3, 20000), rng.normal(0, 1e-6, 500), ties, odd, near]
    )
    for d in (0, 1, 4, 6, 8, 12):
        cells = [bytes(r).replace(b"\0", b"").decode() for r in _fixed(values, d)]
        assert cells == [f"%.{d}f" % v for v in values], d


def _reference_measurements_csv(meas: Measurements, robot) -> str:
    """measurements_to_csv as written row by row before issue 26."""
    scale = np.array(
        [1e3 if j.kind == "prismatic" else 180.0 / np.pi for j in robot.joints]
    )
    cols = [f"j{k + 1}_deg" for k in range(robot.n_joints)]
    data, fmt, labels = [meas.q_ctrl * scale], ["%.8f"] * len(cols), []
    if meas.kind == "sensor":
        labels.append(("target", [meas.target_labels[i] for i in meas.target_index]))
        cols += ["xc_mm", "yc_mm", "zc_mm"]
    else:
        cols += ["x_mm", "y_mm", "z_mm"]
    data.append(meas.p * 1e3)
    fmt += ["%.6f"] * 3
    if meas.kind == "pose":
        cols += ["qw", "qx", "qy", "qz"]
        data.append(matrix_to_quat_wxyz(meas.R_user_cam))
        fmt += ["%.12f"] * 4
    if len(meas.set_labels) > 1 or meas.set_labels[0]:
        labels.append(("set", [meas.set_labels[i] for i in meas.set_index]))
    if len(meas.marker_labels) > 1 or meas.marker_labels[0]:
        labels.append(("marker", [meas.marker_labels[i] for i in meas.marker_index]))
    for name, arr, s in (
        ("payload_kg", meas.payload_kg, 1.0),
        ("sigma_mm", meas.sigma, 1e3),
        ("sigma_deg", meas.sigma_rot, 180.0 / np.pi),
    ):
        if arr is not None:
            cols.append(name)
            data.append(np.asarray(arr)[:, None] * s)
            fmt.append("%.10g")
    num = np.column_stack(data)
    out = [",".join([lab for lab, _ in labels] + cols)]
    for i in range(meas.n):
        lead = [vals[i] for _, vals in labels]
        out.append(",".join(lead + [f % v for f, v in zip(fmt, num[i])]))
    return "\n".join(out) + "\n"


def test_issue_26_measurements_written_byte_for_byte_as_before(rng):
    n = 400
    pose = Measurements(
        "pose",
        rng.uniform(-3, 3, (n, 6)),
        rng.uniform(-1.5, 1.5, (n, 3)),
        R_user_cam=rpy_to_matrix(rng.uniform(-3, 3, (n, 3))),
        set_index=rng.integers(0, 3, n),
        set_labels=("A", "bé", "set 3"),
        marker_index=rng.integers(0, 2, n),
        marker_labels=("m1", "m2"),
        sigma=rng.uniform(1e-6, 1e-4, n),
        sigma_rot=rng.uniform(1e-5, 1e-3, n),
        payload_kg=rng.uniform(0.5, 7.0, n),
    )
    sensor = Measurements(
        "sensor",
        rng.uniform(-3, 3, (n, 6)),
        rng.uniform(-0.02, 0.13, (n, 3)),
        target_index=rng.integers(0, 4, n),
        targets=rng.uniform(0, 1, (4, 3)),
        target_labels=("S1", "S2", "S3", "S4"),
    )
    for m in (pose, sensor):
        assert measurements_to_csv(m, ROBOT) == _reference_measurements_csv(m, ROBOT)


def test_issue_26_table_rewrite_copies_cells_as_written(tmp_path, rng):
    """What `kinecal compensate` writes: new joint values, the other cells as they were,
    the old joints copied into extra columns, diagnostics appended."""
    lines = ["name,j1_deg,x_mm,note"]
    for i in range(300):
        note = ["", " spaced ", "é-ü", "x"][i % 4]
        lines.append(f"p{i},{rng.uniform(-90, 90):.3f},{rng.uniform(-1, 1):.2e},{note}")
    f = tmp_path / "t.csv"
    f.write_text("\n".join(lines) + "\n")
    t = read_table(f)
    new = rng.uniform(-90, 90, len(t))
    cols = [
        ("name", Column.copy_of("name")),
        ("j1_deg", Column.numbers(new, "%.8f")),
        ("x_mm", Column.copy_of("x_mm")),
        ("note", Column.copy_of("note")),
        ("j1_deg_program", Column.copy_of("j1_deg")),
        ("cond", Column.numbers(np.exp(rng.uniform(0, 9, len(t))), "%.4g")),
        ("limit_joint", Column.numbers(rng.integers(0, 7, len(t)), "%d")),
        ("status", Column.text(["ok", "unreachable"] * (len(t) // 2))),
    ]
    got = table_csv(t, cols)
    want = ",".join(n for n, _ in cols) + "\n"
    for i, r in enumerate(t.rows):
        cells = [r[0], f"{new[i]:.8f}", r[2], r[3], r[1]]
        cells += [format(cols[5][1].values[i], ".4g"), str(cols[6][1].values[i])]
        cells.append(cols[7][1].values[i])
        want += ",".join(cells) + "\n"
    assert got == want
    # A file with quoted cells is rewritten row by row, with the same values.
    q = tmp_path / "q.csv"
    q.write_text('a,b\n"1",2\n3,"4"\n')
    tq = read_table(q)
    assert table_csv(tq, [("b", Column.copy_of("b")), ("a", Column.copy_of("a"))]) == (
        "b,a\n2,1\n4,3\n"
    )
    assert csv_text([("v", Column.numbers(np.array([1.25, -0.5]), "%.1f"))]) == (
        "v\n1.2\n-0.5\n"
    )


def test_issue_26_compensate_diagnostic_columns_equal_the_per_row_ones(rng):
    """`kinecal compensate` writes its diagnostics column-wise now (the per-row code
    recomputed a whole column for every row: 44 s for 20,000 targets)."""
    from types import SimpleNamespace

    from kinecal.workflows._compensate import diagnostic_columns as _diagnostic_columns
    from kinecal.workflows._compensate import diagnostics as _diagnostics

    n = 500
    res = SimpleNamespace(
        rotation_error=rng.uniform(0, 1e-3, n),
        cond=np.exp(rng.uniform(0, 12, n)),
        limit_joint=rng.integers(-1, 6, n),
        error=rng.uniform(0, 1e-6, n),
        status=np.array(["ok", "unreachable", "limit"] * (n // 3) + ["ok"] * (n % 3)),
        q_program=rng.uniform(-3, 3, (n, 6)),
    )
    res.q_ctrl = res.q_program + rng.normal(0, 1e-3, (n, 6))
    res.joint_change = res.q_ctrl - res.q_program  # as CompensationResult's
    cols = _diagnostic_columns(res)
    text = csv_text(cols).splitlines()
    assert text[0] == ",".join(name for name, _ in cols)
    assert text[1:] == [",".join(_diagnostics(res, i)) for i in range(n)]
