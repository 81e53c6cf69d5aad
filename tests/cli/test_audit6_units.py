"""Audit 6: joint angles in radians under jK_deg columns in a short file (the reader
tells radians from degrees by the spread of 5 rows or more), in-process."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal
from tests.helpers import calibrate_simulated


@pytest.fixture(scope="module")
def pt(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_point_data(tmp_path_factory.mktemp("audit6_units"))


def _first_rows_in_radians(src: Path, dst: Path, n: int) -> Path:
    lines = src.read_text().splitlines()
    head = lines[0].split(",")
    out = [lines[0]]
    for ln in lines[1 : 1 + n]:
        v = ln.split(",")
        out.append(
            ",".join(
                f"{math.radians(float(x)):.6f}" if h.endswith("_deg") else x
                for h, x in zip(head, v)
            )
        )
    dst.write_text("\n".join(out) + "\n")
    return dst


@pytest.mark.parametrize("n", [1, 3])
def test_compensate_seeds_in_radians_are_refused(pt, capsys, tmp_path, n):
    """Three targets whose program joints were in radians: compensated from those
    poses, J4 moved by about 60 deg, exit 0 (5 rows or more are refused by the
    reader)."""
    tg = _first_rows_in_radians(pt["targets"], tmp_path / "t.csv", n)
    out = tmp_path / "c.csv"
    res = run_kinecal(capsys, "compensate", tg, "--model", pt["model"], "--out", out)
    failed_with(res, "t.csv", "j1_deg..j6_deg", "look like radians", "jK_rad")
    assert not out.exists()
    ok = tmp_path / "ok.csv"
    ok.write_text("\n".join(pt["targets"].read_text().splitlines()[: 1 + n]) + "\n")
    res = run_kinecal(capsys, "compensate", ok, "--model", pt["model"], "--out", out)
    assert res.code == 0, str(res)


def test_evaluate_of_few_rows_in_radians_says_so(pt, capsys, tmp_path):
    """Three rows in radians: refused as 'measurements of another robot or set-up?',
    with nothing on the likelier cause."""
    data = _first_rows_in_radians(pt["test"], tmp_path / "d.csv", 3)
    res = run_kinecal(capsys, "evaluate", data, "--model", pt["model"], "--json")
    failed_with(res, "d.csv", "median error", "radians in jK_deg columns")


def test_evaluate_payload_beyond_ten_times_the_rating_is_refused(capsys, tmp_path):
    """payload_kg 3000 (grams typed as kg) on a 5 kg UR5e in evaluate's data: a
    warning, then scored with exit 0 (compensate's TARGETS, --payload-kg and a
    calibration's payload refuse it)."""
    sim, cal = tmp_path / "sim", tmp_path / "cal"
    res = run_kinecal(
        capsys, "simulate", "--robot", "ur5e", "--payload-kg", "3", "--out", sim,
        "--n-train", "40", "--n-test", "10", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    calibrate_simulated(capsys, sim, cal)
    lines = (sim / "test.csv").read_text().splitlines()
    k = lines[0].split(",").index("payload_kg")

    def with_payload(kg: str) -> Path:
        out = [lines[0]]
        for ln in lines[1:]:
            v = ln.split(",")
            v[k] = kg
            out.append(",".join(v))
        f = tmp_path / f"p{kg}.csv"
        f.write_text("\n".join(out) + "\n")
        return f

    model = cal / "model.yaml"
    res = run_kinecal(capsys, "evaluate", with_payload("3000"), "--model", model)
    failed_with(res, "p3000.csv", "line 2, column 'payload_kg'", "at most 50 kg")
    res = run_kinecal(capsys, "evaluate", with_payload("3"), "--model", model)
    assert res.code == 0, str(res)


@pytest.mark.parametrize("unit", ["metres", "radians"])
def test_one_session_in_other_units_is_named(pt, capsys, tmp_path, unit):
    """Two sessions in one file, the second exported in metres (or its joints in
    radians): the file-wide unit checks passed, and the calibration failed on a
    parameter far off ('are these measurements of another robot?') without naming
    the session."""
    a = pt["train"].read_text().splitlines()
    b = pt["test"].read_text().splitlines()
    head = a[0].split(",")
    rows = [a[0] + ",set"] + [f"{r},A" for r in a[1:]]
    for r in b[1:]:
        v = r.split(",")
        for k, h in enumerate(head):
            if unit == "metres" and h in ("x_mm", "y_mm", "z_mm"):
                v[k] = f"{float(v[k]) / 1000:.9f}"
            if unit == "radians" and h.endswith("_deg"):
                v[k] = f"{math.radians(float(v[k])):.9f}"
        rows.append(",".join(v) + ",B")
    data = tmp_path / "two.csv"
    data.write_text("\n".join(rows) + "\n")
    res = run_kinecal(
        capsys, "calibrate", data, "--robot", "fanuc-lrmate200id", "--model",
        "kinematic", "--cv", "off", "--out", tmp_path / "cal", "-q",
    )  # fmt: skip
    failed_with(res, "two.csv", "set 'B' (from line", f"looks like {unit}")
    assert not (tmp_path / "cal").exists()
