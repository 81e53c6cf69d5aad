"""``kinecal report DIR`` on a report.json whose quantities cannot be right (a hand edit
without the run's manifest.json, which would catch it by its hash): refused naming the
file and the field; what kinecal itself writes passes (every report.json of the suite's
calibrations is drawn through the same check)."""

from __future__ import annotations

import json
import shutil

import pytest

from kinecal.report._summary_check import check_summary
from tests.cli_contract import failed_with, make_point_data, run_kinecal


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    d = tmp_path_factory.mktemp("summary")
    pt = make_point_data(d)
    out = d / "cal"
    res = _calibrate(pt["train"], out)
    assert res.returncode == 0, res.stderr
    (out / "manifest.json").unlink()  # a hand-edited folder: no hashes to compare
    return out


def _calibrate(data, out):
    import subprocess
    import sys

    args = [sys.executable, "-m", "kinecal", "calibrate", str(data), "--robot"]
    args += [
        "fanuc-lrmate200id",
        "--model",
        "kinematic",
        "--cv",
        "off",
        "--out",
        str(out),
    ]
    return subprocess.run(args, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize(
    ("edit", "field"),
    [
        (lambda d: d["after"].__setitem__("rms_mm", "big"), "after.rms_mm"),
        (lambda d: d["before"].__setitem__("max_mm", -2.0), "before.max_mm"),
        (
            lambda d: d["after"].__setitem__("rms_xyz_mm", [0.1, "x", 0.2]),
            "rms_xyz_mm[1]",
        ),
        (lambda d: d["parameters"][0].__setitem__("std", -1.0), "parameters[0].std"),
        (
            lambda d: d["parameters"][1].__setitem__("value", {"a": 1}),
            "parameters[1].value",
        ),
        (lambda d: d["after"].__setitem__("n", 2.5), "after.n"),
        (lambda d: d["before"].__setitem__("rms_mm", True), "before.rms_mm"),
    ],
)
def test_report_refuses_quantities_that_cannot_be_right(
    folder, tmp_path, capsys, edit, field
):
    d = tmp_path / "cal"
    shutil.copytree(folder, d)
    doc = json.loads((d / "report.json").read_text())
    edit(doc)
    (d / "report.json").write_text(json.dumps(doc))
    res = run_kinecal(capsys, "report", d, "--force")
    failed_with(res, "report.json", field)


def test_report_of_the_run_itself_passes(folder, tmp_path, capsys):
    d = tmp_path / "cal"
    shutil.copytree(folder, d)
    doc = json.loads((d / "report.json").read_text())
    check_summary(doc, d / "report.json")
    doc["parameters"][0]["value"] = -1234.5  # a signed quantity: any finite number
    doc["after"]["rot_rms_deg"] = None  # not measured
    (d / "report.json").write_text(json.dumps(doc))
    res = run_kinecal(capsys, "report", d, "--force")
    assert res.code == 0, str(res)
