"""Fuzz: mutated measurement, target and candidate CSV files through calibrate,
evaluate, compensate and plan (issue 21)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from hypothesis import given

from tests.cli_contract import check_contract, leftovers, run_kinecal, snapshot
from tests.fuzz.strategies import FUZZ, mutated_csv

RESULT = {"model.yaml", "report.json", "residuals.csv", "manifest.json"}
ROBOT = "fanuc-lrmate200id"


def _text(path: Path) -> str:
    return path.read_text()


def _example_dir(tmp_path: Path) -> Path:
    return Path(tempfile.mkdtemp(dir=tmp_path))


def test_issue_21_fuzz_calibrate_and_evaluate(point_data, capsys, tmp_path):
    base = _text(point_data["train"])
    earlier = point_data["dir"] / "earlier"
    if not earlier.exists():  # an earlier result that a failed --force run must keep
        shutil.copytree(point_data["dir"], earlier, ignore=lambda d, n: ["earlier"])
        (earlier / "manifest.json").write_text('{"files": ["model.yaml"]}\n')

    @FUZZ
    @given(data=mutated_csv(base))
    def check(data: bytes) -> None:
        d = _example_dir(tmp_path)
        f = d / "data.csv"
        f.write_bytes(data)
        new = d / "new"
        res = run_kinecal(
            capsys,
            "calibrate",
            "--cv",
            "off",
            f,
            "--robot",
            ROBOT,
            "--model",
            "kinematic",
            "--out",
            new,
            "--no-report",
            "-q",
        )
        check_contract(res)
        if res.code in (0, 3):
            assert RESULT <= {p.name for p in new.iterdir()}, str(res)
        else:
            assert not new.exists(), str(res)
        # --force over an earlier result: the new result whole, or the earlier one.
        old = d / "old"
        shutil.copytree(earlier, old)
        before = snapshot(old)
        res2 = run_kinecal(
            capsys,
            "calibrate",
            "--cv",
            "off",
            f,
            "--robot",
            ROBOT,
            "--model",
            "kinematic",
            "--out",
            old,
            "--no-report",
            "--force",
            "-q",
        )
        check_contract(res2)
        if res2.code in (0, 3):
            names = {p.name for p in old.iterdir()}
            assert RESULT <= names and "report.html" not in names, str(res2)
        else:
            assert snapshot(old) == before, str(res2)
        res3 = run_kinecal(
            capsys,
            "evaluate",
            f,
            "--model",
            point_data["model"],
            "--json",
            "--errors-out",
            d / "errors.csv",
        )
        check_contract(res3)
        assert (d / "errors.csv").exists() == (res3.code == 0), str(res3)
        assert not leftovers(d), leftovers(d)

    check()


def test_issue_21_fuzz_compensation_targets(point_data, capsys, tmp_path):
    base = _text(point_data["targets"])

    @FUZZ
    @given(data=mutated_csv(base))
    def check(data: bytes) -> None:
        d = _example_dir(tmp_path)
        f = d / "targets.csv"
        f.write_bytes(data)
        res = run_kinecal(
            capsys,
            "compensate",
            f,
            "--model",
            point_data["model"],
            "--out",
            d / "corrected.csv",
        )
        check_contract(res)
        assert (d / "corrected.csv").exists() == (res.code == 0), str(res)
        assert not leftovers(d)

    check()


def test_issue_21_fuzz_plan_candidates(point_data, capsys, tmp_path):
    base = _text(point_data["test"])

    @FUZZ
    @given(data=mutated_csv(base))
    def check(data: bytes) -> None:
        d = _example_dir(tmp_path)
        f = d / "cand.csv"
        f.write_bytes(data)
        res = run_kinecal(
            capsys,
            "plan",
            "--robot",
            ROBOT,
            "--candidates",
            f,
            "--poses",
            "12",
            "--model",
            "kinematic",
            "--out",
            d / "plan.csv",
            "--random-draws",
            "2",
            "--exchange",
            "none",
            "-q",
        )
        check_contract(res)
        written = (d / "plan.csv").exists(), (d / "plan.report.json").exists()
        assert written == ((res.code == 0),) * 2, str(res)
        assert not leftovers(d)

    check()
