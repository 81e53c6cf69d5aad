"""Issue 21 audit (data files and options of calibrate, evaluate, plan): faults a new
user meets that ended in a hang, an internal error or an answer with exit 0, now one
``Error:`` line and exit 2. In-process, on tiny files checked before any fit."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.cli_contract import failed_with, run_kinecal

ROBOT = "fanuc-lrmate200id"
JOINTS = [f"j{k}_deg" for k in range(1, 7)]


_bad = failed_with


def _poses(n: int, seed: int = 0) -> np.ndarray:
    """(n, 6) joint angles [deg] well inside the LR Mate's limits, all different."""
    rng = np.random.default_rng(seed)
    return rng.uniform(
        [-60, -20, -30, -90, -90, -90], [60, 40, 30, 90, -30, 90], (n, 6)
    )


def _csv(path: Path, header: list[str], rows) -> Path:
    lines = [",".join(header)] + [",".join(str(v) for v in r) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def _points(tmp_path: Path, n: int = 12, extra=None, name: str = "data.csv") -> Path:
    """A point-data CSV (the positions need not fit: these runs stop at the checks)."""
    q = _poses(n)
    p = np.column_stack([600 + q[:, 0], 10 * q[:, 1], 300 + q[:, 2]])
    header = [*JOINTS, "x_mm", "y_mm", "z_mm"]
    rows = [list(a) + list(b) for a, b in zip(q.round(4), p.round(4))]
    if extra:
        col, values = extra
        header.append(col)
        rows = [[*r, v] for r, v in zip(rows, values)]
    return _csv(tmp_path / name, header, rows)


def _calibrate(capsys, data, tmp_path, *args):
    out = tmp_path / "out"
    res = run_kinecal(
        capsys, "calibrate", data, "--robot", ROBOT, "--out", out, "-q", "--no-report",
        *args,
    )  # fmt: skip
    assert not out.exists(), str(res)
    return res


# --- implausible cells: a hang (1e300 mm) and an internal error (1e300 kg) --------


def test_issue_21_audit_position_of_1e300_mm_is_refused(capsys, tmp_path):
    f = _points(tmp_path)
    lines = f.read_text().splitlines()
    cells = lines[4].split(",")
    cells[6] = "1e300"
    lines[4] = ",".join(cells)
    f.write_text("\n".join(lines) + "\n")
    res = _calibrate(capsys, f, tmp_path, "--model", "kinematic")
    _bad(res, "data.csv", "line 5", "x_mm", "expected positions within 1e+06 mm")


def test_issue_21_audit_payload_of_1e300_kg_is_refused(capsys, tmp_path):
    f = _points(tmp_path, extra=("payload_kg", [1.0] * 5 + ["1e300"] + [1.0] * 6))
    res = _calibrate(capsys, f, tmp_path)
    _bad(res, "data.csv", "line 7", "'payload_kg'", "expected a value up to 100000")


def test_issue_21_audit_far_target_and_far_sensor_reading_are_refused(capsys, tmp_path):
    tg = _csv(
        tmp_path / "targets.csv",
        ["target", "x_mm", "y_mm", "z_mm"],
        [["S1", 100, 400, 2300], ["S2", "1e300", 300, 2600], ["S3", 50, 350, 2400]],
    )
    q = _poses(12)
    rows = [["S1", *r, 1.0, -0.5, 120.0] for r in q.round(4)]
    f = _csv(
        tmp_path / "sensor.csv", ["target", *JOINTS, "xc_mm", "yc_mm", "zc_mm"], rows
    )
    res = _calibrate(capsys, f, tmp_path, "--model", "kinematic", "--targets", tg)
    _bad(res, "targets.csv", "line 3", "expected positions within 1e+06 mm")
    rows[3][7] = "-1e300"
    f = _csv(
        tmp_path / "sensor.csv", ["target", *JOINTS, "xc_mm", "yc_mm", "zc_mm"], rows
    )
    tg = _csv(
        tmp_path / "targets.csv",
        ["target", "x_mm", "y_mm", "z_mm"],
        [["S1", 100, 400, 2300], ["S2", 0, 300, 2600]],
    )
    res = _calibrate(capsys, f, tmp_path, "--model", "kinematic", "--targets", tg)
    _bad(res, "sensor.csv", "line 5", "xc_mm", "expected positions within 1e+06 mm")


# --- options ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--reject-z", "nan"], ["--reject-z", "finite", "nan"]),
        (["--reject-z", "inf"], ["--reject-z", "finite", "inf"]),
        (["--ntm-joints", ""], ["--ntm-joints", "expected comma-separated"]),
        (["--ntm-joints", "1,1"], ["--ntm-joints", "joint 1 is given twice"]),
        (["--ntm-joints", "2,7"], ["--ntm-joints", "joint 7", "1 to 6"]),
    ],
)
def test_issue_21_audit_calibrate_options(capsys, tmp_path, args, needles):
    res = _calibrate(capsys, _points(tmp_path), tmp_path, "--model", "ntm", *args)
    _bad(res, *needles)


@pytest.mark.parametrize("n", [5, 8, 12])
def test_issue_21_audit_model_auto_on_too_few_poses(capsys, tmp_path, n):
    """Was an internal error (no candidate could be cross-validated)."""
    res = _calibrate(capsys, _points(tmp_path, n), tmp_path, "--model", "auto")
    _bad(res, "data.csv", "--model auto", "5 folds", "expected at least 13 poses")


# --- plan ------------------------------------------------------------------------


def _plan(capsys, tmp_path, *args):
    out = tmp_path / "plan.csv"
    res = run_kinecal(
        capsys, "plan", "--robot", ROBOT, "--out", out, "-q", "--model", "kinematic",
        "--random-draws", "2", *args,
    )  # fmt: skip
    assert not out.exists(), str(res)
    return res


def test_issue_21_audit_plan_candidates_in_radians(capsys, tmp_path):
    f = _csv(tmp_path / "cand.csv", JOINTS, np.radians(_poses(40)).round(6))
    res = _plan(capsys, tmp_path, "--candidates", f, "--poses", "10")
    _bad(res, "cand.csv", "j1_deg..j6_deg", "looks like radians")


def test_issue_21_audit_plan_from_copies_of_one_pose(capsys, tmp_path):
    f = _csv(tmp_path / "cand.csv", JOINTS, [_poses(1)[0].round(4)] * 50)
    res = _plan(capsys, tmp_path, "--candidates", f, "--poses", "5")
    _bad(res, "cand.csv", "50 rows hold only 1 distinct pose", "--poses 5")


def test_issue_21_audit_plan_zero_width_joint_ranges(capsys, tmp_path):
    rng = "J1:5:5,J2:5:5,J3:5:5,J4:5:5,J5:-40:-40,J6:5:5"
    res = _plan(
        capsys, tmp_path, "--joint-range", rng, "--poses", "20", "--n-candidates", "20"
    )
    _bad(res, "generated candidates", "only 1 distinct pose", "--poses 20")


def test_issue_21_audit_plan_no_candidate_message(capsys, tmp_path):
    res = _plan(
        capsys, tmp_path, "--poses", "5", "--n-candidates", "10", "--min-j5-deg", "400"
    )
    last = _bad(res, "no acceptable candidate", "--min-j5-deg")
    assert "{" not in last  # no Python dict in the message


def test_issue_21_audit_plan_standoff_text(capsys, tmp_path):
    tg = _csv(tmp_path / "t.csv", ["target", "x_mm", "y_mm", "z_mm"], [["S1", 0, 0, 0]])
    res = _plan(
        capsys, tmp_path, "--instrument", "sensor", "--targets", tg, "--poses", "5",
        "--standoff-mm", "abc",
    )  # fmt: skip
    _bad(res, "--standoff-mm", "0 < LO <= HI", "'abc'")
