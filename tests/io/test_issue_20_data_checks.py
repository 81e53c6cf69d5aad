"""Issue 20, point 3: rows that cannot be right are refused (file, line, column, value,
reason); findings that do not stop a run are warnings with a code. Each case is a mistake
met on real data; the shipped UR10 and FR3 files (tests/data/real) must pass clean."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.identification import Measurements
from kinecal.io import (
    DataWarning,
    data_diagnostics,
    measurements_to_csv,
    read_data,
    read_measurements,
    read_targets,
)
from kinecal.robot import load_robot

REAL = Path(__file__).resolve().parents[1] / "data" / "real"
FANUC = load_robot("fanuc-lrmate200id")
FR3 = load_robot("franka-fr3")
UR10E = load_robot("ur10e")


def _fanuc_points(rng, n=30, **kw) -> Measurements:
    lim = FANUC.limits * 0.8
    q = rng.uniform(lim[:, 0], lim[:, 1], (n, 6))
    p = FANUC.fk_flange(q)[:, :3, 3] + [0.4, 0.1, 0.0]
    return Measurements("point", q, p, **kw)


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _codes(found) -> list[str]:
    return [d.code for d in found]


def _edit_cell(text: str, line: int, column: str, value: str) -> str:
    """``text`` with the cell of (1-based file) ``line`` in ``column`` replaced."""
    lines = text.splitlines()
    k = lines[0].split(",").index(column)
    cells = lines[line - 1].split(",")
    cells[k] = value
    lines[line - 1] = ",".join(cells)
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------- clean real data
@pytest.mark.parametrize(
    ("name", "robot"),
    [
        ("ur10_mocap.csv", UR10E),
        ("fr3_session_a.csv", FR3),
        ("fr3_session_b_board_moved.csv", FR3),
    ],
)
def test_issue_20_shipped_real_data_pass_without_findings(name, robot):
    _, found = read_data(REAL / name, robot)
    assert found == [], [d.message for d in found]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_measurements(REAL / name, robot)


# ---------------------------------------------------------------- refused rows
def test_issue_20_joint_beyond_limits_is_refused_with_line_column_and_value(tmp_path):
    text = (REAL / "fr3_session_a.csv").read_text()
    # FR3 J4 lies in [-174.3, -8.7] deg; +5 deg is a different robot or a zero mistake.
    f = _write(tmp_path / "fr3.csv", _edit_cell(text, 12, "j4_deg", "5.0"))
    with pytest.raises(DataError) as info:
        read_measurements(f, FR3)
    msg = str(info.value)
    assert msg.startswith(str(f)) and "\n" not in msg
    assert "line 12, column 'j4_deg': 5 is outside the limits [-174.3, -8.7]" in msg
    assert "--allow-out-of-limits" in msg
    # Accepted on request, with a warning that counts the rows and names the first.
    meas, found = read_data(f, FR3, allow_out_of_limits=True)
    assert meas.n == 60 and _codes(found) == ["out_of_limits"]
    assert found[0].rows == (12,) and "J4 (1)" in found[0].message
    with pytest.warns(DataWarning, match="beyond the joint limits"):
        read_measurements(f, FR3, allow_out_of_limits=True)


def test_issue_20_a_wild_joint_value_is_refused_even_when_asked(tmp_path):
    """--allow-out-of-limits accepts a robot a little beyond its limits, not 1e300 deg
    or a column of another quantity (issue 21 audit: the row was rejected as a gross
    error, exit 0)."""
    text = (REAL / "fr3_session_a.csv").read_text()
    for value in ("1e300", "200.0"):  # J4 in [-174.3, -8.7]: 200 deg is within a turn
        f = _write(tmp_path / "fr3.csv", _edit_cell(text, 9, "j4_deg", value))
        if value == "200.0":
            _, found = read_data(f, FR3, allow_out_of_limits=True)
            assert _codes(found) == ["out_of_limits"]
            continue
        with pytest.raises(DataError, match=r"line 9, column 'j4_deg': 1e\+300 is not"):
            read_data(f, FR3, allow_out_of_limits=True)


def test_issue_20_joint_within_the_one_degree_margin_is_accepted(tmp_path):
    text = (REAL / "fr3_session_a.csv").read_text()
    f = _write(tmp_path / "fr3.csv", _edit_cell(text, 5, "j4_deg", "-8.0"))  # 0.7 deg
    _, found = read_data(f, FR3)
    assert "out_of_limits" not in _codes(found)
    g = _write(tmp_path / "fr3b.csv", _edit_cell(text, 5, "j4_deg", "-7.5"))  # 1.2 deg
    with pytest.raises(DataError, match=r"line 5, column 'j4_deg': -7.5 is outside"):
        read_data(g, FR3)


@pytest.mark.parametrize(
    ("column", "meant"),
    [
        ("markers", "marker"),
        ("Marker", "marker"),
        ("sets", "set"),
        ("Set", "set"),
        ("payload_g", "payload_kg"),
        ("sigma_um", "sigma_mm"),
        ("X_mm", "x_mm"),
        ("J1_deg", "j1_deg"),
    ],
)
def test_issue_20_near_miss_column_names_are_refused(tmp_path, column, meant):
    """A near-miss optional column was silently ignored (one user frame for two
    sessions: an 11.7 mm fit); now: did you mean?"""
    lines = (REAL / "fr3_session_a.csv").read_text().splitlines()
    if column.lower().startswith(("x_", "j1_")):
        lines[0] = lines[0].replace(meant, column, 1)
    else:
        lines = [f"{column}," + lines[0]] + [f"1,{s}" for s in lines[1:]]
    f = _write(tmp_path / "near.csv", "\n".join(lines) + "\n")
    with pytest.raises(DataError, match=rf"column '{column}' .*did you mean '{meant}'"):
        read_measurements(f, FR3)


@pytest.mark.parametrize("column", ["seq", "time_s", "operator", "temperature_c"])
def test_issue_20_other_extra_columns_stay_allowed(tmp_path, column):
    lines = (REAL / "fr3_session_a.csv").read_text().splitlines()
    lines = [f"{column}," + lines[0]] + [f"{i},{s}" for i, s in enumerate(lines[1:])]
    f = _write(tmp_path / "extra.csv", "\n".join(lines) + "\n")
    assert read_data(f, FR3)[0].n == 60


def test_issue_20_the_sets_typo_on_two_sessions(tmp_path):
    a = (REAL / "fr3_session_a.csv").read_text().splitlines()
    b = (REAL / "fr3_session_b_board_moved.csv").read_text().splitlines()
    both = ["sets," + a[0]] + ["A," + r for r in a[1:]] + ["B," + r for r in b[1:]]
    f = _write(tmp_path / "both.csv", "\n".join(both) + "\n")
    with pytest.raises(DataError, match="did you mean 'set'"):
        read_measurements(f, FR3)
    g = _write(tmp_path / "ok.csv", "\n".join(both).replace("sets,", "set,", 1) + "\n")
    assert read_measurements(g, FR3).set_labels == ("A", "B")


def test_issue_20_targets_file_in_metres_is_refused(tmp_path):
    f = _write(
        tmp_path / "t.csv",
        "target,x_mm,y_mm,z_mm,r_mm\nS1,0.1853,0.4084,2.3039,0.015\n"
        "S2,0.2404,0.3779,2.6409,0.015\n",
    )
    with pytest.raises(DataError, match=r"t.csv: columns x_mm, y_mm, z_mm: .*metres"):
        read_targets(f)
    one = _write(tmp_path / "one.csv", "target,x_mm,y_mm,z_mm,r_mm\nS1,0,0,0,0.015\n")
    with pytest.raises(DataError, match=r"column 'r_mm': .*metres"):
        read_targets(one)
    # A single sphere at the origin of its own frame, in mm, is fine.
    good = _write(tmp_path / "good.csv", "target,x_mm,y_mm,z_mm,r_mm\nS1,0,0,0,15\n")
    assert read_targets(good).radius[0] == pytest.approx(0.015)


def test_issue_20_sensor_points_in_metres_are_refused(tmp_path, rng):
    q = rng.uniform(-40, 40, (8, 6))
    pc = np.array([0.0, 0.0, 0.125]) + rng.uniform(-0.02, 0.02, (8, 3))  # metres
    rows = [",".join(f"{v:.5f}" for v in (*qq, *pp)) for qq, pp in zip(q, pc)]
    head = "target,j1_deg,j2_deg,j3_deg,j4_deg,j5_deg,j6_deg,xc_mm,yc_mm,zc_mm"
    f = _write(tmp_path / "s.csv", head + "\n" + "\n".join("S1," + r for r in rows))
    t = _write(tmp_path / "t.csv", "target,x_mm,y_mm,z_mm\nS1,185.3,408.4,2303.9\n")
    with pytest.raises(DataError, match=r"columns xc_mm, yc_mm, zc_mm: .*metres"):
        read_measurements(f, FANUC, t)


# ---------------------------------------------------------------- warnings
def test_issue_20_duplicated_rows_are_reported(tmp_path):
    lines = (REAL / "fr3_session_a.csv").read_text().splitlines()
    dup = [*lines, lines[5], lines[9], lines[5]]  # file lines 6, 10, 6 again
    f = _write(tmp_path / "dup.csv", "\n".join(dup) + "\n")
    meas, found = read_data(f, FR3)
    assert meas.n == 63 and _codes(found) == ["duplicate_rows"]
    assert found[0].rows == (62, 63, 64)
    assert "3 rows repeat an earlier row" in found[0].message


def test_issue_20_payload_beyond_the_rating(tmp_path, rng):
    m = _fanuc_points(rng, payload_kg=np.full(30, 2.0))
    text = measurements_to_csv(m, FANUC)
    f = _write(tmp_path / "p.csv", _edit_cell(text, 7, "payload_kg", "2500"))  # grams
    _, found = read_data(f, FANUC)
    assert _codes(found) == ["payload_over_rating"]
    assert found[0].rows == (7,)
    assert "2500 kg" in found[0].message and "7 kg rated payload" in found[0].message
    _, ok = read_data(_write(tmp_path / "ok.csv", text), FANUC)
    assert ok == []


def _swap_quaternion_order(text: str) -> str:
    """The file a user writes from x, y, z, w quaternions under qw, qx, qy, qz."""
    lines = text.splitlines()
    head = lines[0].split(",")
    k = [head.index(c) for c in ("qw", "qx", "qy", "qz")]
    out = [lines[0]]
    for ln in lines[1:]:
        c = ln.split(",")
        w, x, y, z = (c[i] for i in k)
        for i, v in zip(k, (x, y, z, w)):
            c[i] = v
        out.append(",".join(c))
    return "\n".join(out) + "\n"


@pytest.mark.parametrize(
    ("name", "robot"), [("ur10_mocap.csv", UR10E), ("fr3_session_a.csv", FR3)]
)
def test_issue_20_quaternions_in_xyzw_order_are_detected(tmp_path, name, robot):
    text = _swap_quaternion_order((REAL / name).read_text())
    f = _write(tmp_path / name, text)
    _, found = read_data(f, robot)
    assert _codes(found) == ["quaternion_order"]
    read_deg, other_deg = (
        float(x) for x in re.findall(r"by ([\d.]+) deg", found[0].message)[:2]
    )
    assert read_deg > 10.0 and other_deg < 1.0
    assert "put w first" in found[0].message


def test_issue_20_poses_that_do_not_excite_a_joint(tmp_path, rng):
    m = _fanuc_points(rng)
    q = m.q_ctrl.copy()
    q[:, 0] = np.radians(12.0)  # all poses at the same J1
    q[:, 5] = np.radians(30.0) + np.radians(0.5) * rng.standard_normal(q.shape[0])
    still = Measurements("point", q, FANUC.fk_flange(q)[:, :3, 3])
    found = data_diagnostics(still, FANUC)
    assert _codes(found) == ["poor_excitation"]
    assert re.search(
        r"J1, J6 hardly move \(range J1 0 deg, J6 [\d.]+ deg", found[0].message
    )
    # One tool orientation: only a translation of the flange.
    q1 = np.tile(np.radians([0.0, 10.0, -20.0, 0.0, -60.0, 0.0]), (10, 1))
    q1[:, 0] += np.radians(np.linspace(-1.0, 1.0, 10))
    q1[:, 1] += np.radians(np.linspace(-2.0, 2.0, 10))
    found = data_diagnostics(Measurements("point", q1, q1[:, :3]), FANUC)
    assert any("tool orientation hardly changes" in d.message for d in found)
    assert data_diagnostics(m, FANUC) == []
