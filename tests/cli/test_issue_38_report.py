"""Issue 38 points 1, 3, 4: acceptance limits, held-out accuracy by default, the
certificate fields and the comparison of two calibrations, through the CLI in this
process."""

from __future__ import annotations

import json

import pytest

from tests.cli_contract import check_contract, run_kinecal


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    d = tmp_path_factory.mktemp("twin38")
    pytest.importorskip("kinecal.cli")
    from kinecal.cli import main

    code = main(
        ["simulate", "--out", str(d / "sim"), "--n-train", "60", "--seed", "3", "-q"]
    )
    assert code in (0, None)
    return d


def _calibrate(capsys, twin, name, *extra):
    res = run_kinecal(
        capsys, "calibrate", twin / "sim" / "train.csv", "--robot", "fanuc-lrmate200id",
        "--model", "kinematic", "--out", twin / name, "--no-report", *extra,
    )  # fmt: skip
    check_contract(res)
    return res


def test_accept_verdict_console_json_exit_code(twin, capsys):
    res = _calibrate(capsys, twin, "acc_pass", "--accept", "100,500")
    assert res.code == 0
    assert "accept    PASS" in res.out and "calibration data" in res.out
    acc = json.loads((twin / "acc_pass" / "report.json").read_text())["acceptance"]
    assert acc["pass"] is True and acc["rms_limit_mm"] == 100.0
    assert acc["max_limit_mm"] == 500.0
    assert [c["figure"] for c in acc["checks"]] == ["rms_mm", "max_mm"]
    assert acc["max_mm"] >= acc["rms_mm"] > 0
    from kinecal.report import write_report

    write_report(twin / "acc_pass", force=True)
    html = (twin / "acc_pass" / "report.html").read_text()
    assert "Acceptance: PASS" in html and "judged on" in html
    # a limit below the fit's own RMS fails; the exit code stays 0
    res = _calibrate(capsys, twin, "acc_fail", "--accept", "1e-6")
    assert res.code == 0
    assert "accept    FAIL" in res.out
    acc = json.loads((twin / "acc_fail" / "report.json").read_text())["acceptance"]
    assert acc["pass"] is False and acc["checks"][0]["pass"] is False


@pytest.mark.parametrize("bad", ["abc", "0", "1,2,3", "-1", "nan"])
def test_accept_bad_limits(twin, capsys, bad):
    res = _calibrate(capsys, twin, f"bad_{len(bad)}", "--accept", bad)
    assert res.code == 2 and "--accept" in res.err
