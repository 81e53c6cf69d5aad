"""Fuzz: hand-edited model.yaml files through evaluate, fk, export-urdf, compensate,
plan and report; mutated controller programs through compensate (issue 21)."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from hypothesis import given
from hypothesis import strategies as st

from tests.cli_contract import check_contract, leftovers, run_kinecal
from tests.fuzz.strategies import FUZZ, mutated_csv, mutated_doc, mutated_text

PROGRAMS = Path(__file__).resolve().parents[1] / "data" / "programs"
ZEROS = ["0"] * 6


def test_issue_21_fuzz_model_file(point_data, capsys, tmp_path):
    from kinecal import _yaml as yaml

    text = point_data["model"].read_text()
    doc = yaml.load(text)

    @FUZZ
    @given(
        model=st.one_of(
            mutated_doc(doc).map(lambda d: yaml.dump(d, sort_keys=False)),
            mutated_text(text),
        )
    )
    def check(model: str) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        f = d / "model.yaml"
        f.write_text(model)
        for args in (
            ["evaluate", point_data["test"], "--model", f, "--json"],
            ["fk", "--model", f, "--json", "--", *ZEROS],
            ["export-urdf", f, "--out", d / "cal.urdf", "--data", point_data["test"]],
            ["compensate", point_data["targets"], "--model", f, "--out", d / "c.csv"],
        ):
            check_contract(run_kinecal(capsys, *args))
        assert not leftovers(d)

    check()


def test_issue_21_fuzz_report_folder(point_data, capsys, tmp_path):
    """`kinecal report DIR` on a folder whose report.json or residuals.csv is damaged."""
    from kinecal import _yaml as yaml

    src = tmp_path / "src"
    res = run_kinecal(
        capsys,
        "calibrate",
        point_data["train"],
        "--robot",
        "fanuc-lrmate200id",
        "--model",
        "kinematic",
        "--out",
        src,
        "--no-report",
        "-q",
    )
    assert res.code == 0, str(res)
    import json

    report = json.loads((src / "report.json").read_text())
    residuals = (src / "residuals.csv").read_text()

    @FUZZ
    @given(
        which=st.sampled_from(["report", "residuals"]),
        report_text=mutated_doc(report).map(json.dumps)
        | mutated_text(json.dumps(report, indent=1)),
        residuals_bytes=mutated_csv(residuals),
    )
    def check(which: str, report_text: str, residuals_bytes: bytes) -> None:
        d = Path(tempfile.mkdtemp(dir=tmp_path)) / "cal"
        shutil.copytree(src, d)
        if which == "report":
            (d / "report.json").write_text(report_text)
        else:
            (d / "residuals.csv").write_bytes(residuals_bytes)
        r = run_kinecal(capsys, "report", d, "-q")
        check_contract(r)
        assert (d / "report.html").exists() == (r.code == 0), str(r)
        assert not leftovers(d.parent)

    del yaml
    check()


def test_issue_21_fuzz_programs(point_data, capsys, tmp_path):
    files = sorted(p for p in PROGRAMS.iterdir() if p.suffix != ".md")
    texts = {p.suffix: p.read_text() for p in files}

    @FUZZ
    @given(
        suffix=st.sampled_from(sorted(texts)),
        data=st.data(),
    )
    def check(suffix: str, data: st.DataObject) -> None:
        text = data.draw(mutated_text(texts[suffix]))
        d = Path(tempfile.mkdtemp(dir=tmp_path))
        f = d / f"prog{suffix}"
        f.write_text(text)
        out = d / f"out{suffix}"
        res = run_kinecal(
            capsys,
            "compensate",
            f,
            "--model",
            point_data["model"],
            "--out",
            out,
            "--allow-unreachable",
        )
        check_contract(res)
        assert out.exists() == (res.code == 0), str(res)
        assert not leftovers(d)

    check()
