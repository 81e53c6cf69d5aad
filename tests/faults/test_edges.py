"""Issue 35, "Edges": a failing ``--force`` run leaves the earlier result as it was
(everything a command prints or writes is computed before its files are replaced, and
two outputs never share a file); a run that ends non-zero ends on its ``Error:`` line
(exit 3 too, after its summary); a marker or set seen in one row is warned about;
messages never name ``set ''`` / ``marker ''``, a staged temporary folder, or a file
twice."""

from __future__ import annotations

import dataclasses
import os
import shutil
from pathlib import Path

import pytest

from tests.cli_contract import check_contract, failed_with, run_kinecal, snapshot

ROBOT = "fanuc-lrmate200id"
PLAN = ("--poses", "12", "--model", "kinematic", "--n-candidates", "200")
PLAN += ("--random-draws", "2", "-q")


@pytest.fixture
def work(data, tmp_path):
    for k in ("train", "test", "model"):
        shutil.copy(data[k], tmp_path / data[k].name)
    return tmp_path


@pytest.fixture
def planned(capsys, work):
    """A plan (PLAN.csv and its report) made earlier in ``work``."""
    res = run_kinecal(capsys, "plan", "--robot", ROBOT, "--out", work / "p.csv", *PLAN)
    assert res.code == 0, str(res)
    assert (work / "p.report.json").is_file()
    return work


def test_issue_35_a_failing_plan_force_leaves_the_earlier_plan(
    capsys, planned, monkeypatch
):
    from kinecal.workflows._plan import PlanRun

    before = snapshot(planned)
    args = ("plan", "--robot", ROBOT, "--out", planned / "p.csv", "--force")
    # fails at its arguments, at its candidates, and late (after the plan is chosen)
    res = run_kinecal(capsys, *args, *PLAN, "--poses", "5000")
    failed_with(res, "5000 poses asked")
    assert snapshot(planned) == before

    def late(*a, **k):
        raise RuntimeError("a failure after the plan was chosen")

    monkeypatch.setattr(PlanRun, "summary_lines", late)
    res = run_kinecal(capsys, *args, *PLAN, "--criterion", "D")
    assert res.code == 1 and "a failure after the plan" in res.err, str(res)
    assert snapshot(planned) == before  # nothing replaced: the files come last


@pytest.mark.parametrize(
    "extra",
    [
        ("--report", "p.csv"),  # the report onto the plan
        ("--save-candidates", "p.report.json"),  # the candidates onto the report
        ("--report", "./sub/../p.csv"),  # another spelling of the plan
    ],
)
def test_issue_35_two_outputs_of_plan_onto_one_file(capsys, planned, extra):
    (planned / "sub").mkdir()
    before = snapshot(planned)
    option, name = extra
    res = run_kinecal(
        capsys, "plan", "--robot", ROBOT, "--out", planned / "p.csv", "--force",
        option, planned / name, *PLAN,
    )  # fmt: skip
    line = failed_with(res, "two outputs of this command")
    assert line.count("p.csv") + line.count("p.report.json") <= 2
    assert snapshot(planned) == before


def test_issue_35_two_outputs_of_plan_iso9283_onto_one_file(capsys, work):
    out = work / "iso.csv"
    res = run_kinecal(
        capsys, "plan", "--robot", ROBOT, "--iso9283", "--out", out, "--report", out
    )
    failed_with(res, "two outputs of this command")
    assert not out.exists()


def test_issue_35_outputs_one_file_under_two_names(tmp_path):
    from kinecal.errors import ConfigError
    from kinecal.io._files import atomic_write_files, check_distinct_outputs

    a = tmp_path / "a.csv"
    a.write_text("old\n")
    os.symlink(a, tmp_path / "link.csv")
    check_distinct_outputs([a, tmp_path / "b.csv", None])  # distinct: fine
    for other in (tmp_path / "link.csv", f"{tmp_path}/./a.csv"):
        with pytest.raises(ConfigError, match="two outputs"):
            atomic_write_files({str(a): "x", str(other): "y"}, force=True)
    assert a.read_text() == "old\n"


def test_issue_35_evaluate_force_that_fails_keeps_errors_out(capsys, work):
    errors = work / "errors.csv"
    errors.write_text("earlier errors\n")
    before = snapshot(work)
    common = ("evaluate", work / "test.csv", "--model", work / "model.yaml")
    common += ("--errors-out", errors, "--force", "-q")
    # --out without --iso9283: a usage error, found before any work
    failed_with(run_kinecal(capsys, *common, "--out", work / "iso"), "--out is for")
    # --iso9283 on data that are not an ISO test: refused after the evaluation
    failed_with(run_kinecal(capsys, *common, "--iso9283"), "iso_point")
    assert snapshot(work) == before


def test_issue_35_not_converged_ends_on_its_error_line(capsys, work, monkeypatch):
    """Exit 3: the results are written, the summary printed, then one ``Error:`` line
    last on stderr (not a warning line)."""
    import kinecal.workflows._calibrate as wf
    from kinecal.measurement import Diagnostic

    real = wf.calibrate

    def not_converged(*a, **k):
        res = real(*a, **k)
        res.diagnostics.append(
            Diagnostic("not_converged", "stage 1 did not converge: (test)")
        )
        return dataclasses.replace(res, success=False)

    monkeypatch.setattr(wf, "calibrate", not_converged)
    out = work / "cal"
    res = run_kinecal(
        capsys, "calibrate", work / "train.csv", "--robot", ROBOT, "--out", out,
        "--model", "kinematic", "--cv", "off", "-q",
    )  # fmt: skip
    check_contract(res)
    assert res.code == 3, str(res)
    last = res.err.strip().splitlines()[-1]
    assert "did not converge" in last and str(out) in last, str(res)
    assert "warning   stage 1 did not converge" in res.err  # the warning comes before
    assert res.out.strip().splitlines()[-1].startswith("wrote")  # the summary: complete
    assert (out / "model.yaml").is_file() and (out / "manifest.json").is_file()


def _with_column(src: Path, dst: Path, name: str, last: str, others: str) -> Path:
    lines = src.read_text().splitlines()
    rows = [f"{r},{others}" for r in lines[1:-1]] + [f"{lines[-1]},{last}"]
    dst.write_text("\n".join([f"{lines[0]},{name}", *rows]) + "\n")
    return dst


def test_issue_35_a_marker_seen_in_one_row_is_warned_about(capsys, work):
    data = _with_column(work / "train.csv", work / "m.csv", "marker", "m2", "m1")
    n_lines = len(data.read_text().splitlines())
    res = run_kinecal(
        capsys, "calibrate", data, "--robot", ROBOT, "--out", work / "cal",
        "--model", "kinematic", "--cv", "off", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    warned = [ln for ln in res.err.splitlines() if "marker 'm2'" in ln]
    assert warned and f"one row only (line {n_lines})" in warned[0], str(res)
    assert "marker 'm1'" not in res.err


def test_issue_35_the_lone_label_check():
    """One row of a set or marker among several: a finding per label, naming its line;
    a single label (however many rows) or two rows each: none."""
    import numpy as np

    from kinecal.io._checks import lone_labels
    from kinecal.measurement import Measurements

    n = 6
    meas = Measurements(
        "point", np.zeros((n, 6)), np.zeros((n, 3)), source="d.csv",
        set_index=np.array([0, 0, 0, 0, 0, 1]), set_labels=("A", "B"),
        marker_index=np.array([0, 1, 1, 0, 0, 0]), marker_labels=("m1", "m2"),
        rows=np.arange(2, n + 2),
    )  # fmt: skip
    found = lone_labels(meas)
    assert [d.code for d in found] == ["lone_label"]
    assert "set 'B'" in found[0].message and "(line 7)" in found[0].message
    one = dataclasses.replace(meas, set_index=np.zeros(n, np.intp), set_labels=("A",))
    assert lone_labels(one) == []


def test_issue_35_messages_never_name_the_empty_label(capsys, work):
    """The model of data without a set or marker column has the default ones (``''``):
    messages say so in words."""
    sets = _with_column(work / "test.csv", work / "s.csv", "set", "B", "A")
    model = work / "model.yaml"
    runs = [
        run_kinecal(capsys, "evaluate", sets, "--model", model, "-q"),
        run_kinecal(
            capsys,
            "fk",
            "--model",
            model,
            "--marker",
            "x",
            "--",
            *"0 0 0 0 -30 0".split(),
        ),
        run_kinecal(
            capsys, "export-urdf", model, "--out", work / "c.urdf", "--set", "x"
        ),
    ]
    for res in runs:
        line = failed_with(res)
        assert "''" not in line, line
    assert "the model has one set:" in runs[0].err
    assert "only the default marker" in runs[1].err


def test_issue_35_an_input_refused_as_output_is_named_once(capsys, work):
    data = work / "test.csv"
    res = run_kinecal(
        capsys, "evaluate", data, "--model", work / "model.yaml", "--errors-out", data,
        "--force",
    )  # fmt: skip
    line = failed_with(res, "is an input of this command (DATA)")
    assert line.count(str(data)) == 1, line
    res = run_kinecal(
        capsys, "export-urdf", work / "model.yaml", "--out", work / "model.yaml",
        "--force",
    )  # fmt: skip
    line = failed_with(res, "(MODEL.yaml)")
    assert line.count("model.yaml") == 1, line


def test_issue_35_messages_name_the_result_folder_not_its_staging():
    from kinecal.cli._errors import one_line

    assert one_line("/r/.out.kinecal-tmp-12-ab12cd34/model.yaml: bad") == (
        "/r/out/model.yaml: bad"
    )
    assert one_line("x /r/out/.kinecal-tmp-12-ab12cd34/report.json y") == (
        "x /r/out/report.json y"
    )


@pytest.mark.parametrize(
    "extra, needle",
    [
        (("--data", "train.csv"), "--data is for --model MODEL.yaml --add N"),
        (
            ("--candidates", "p.csv", "--station", "1,2,3"),
            "is for generated candidates",
        ),
        (
            ("--candidates", "p.csv", "--n-candidates", "99"),
            "is for generated candidates",
        ),
        (("--cube-mm", "100"), "--cube-mm is for --iso9283"),
        (("--standoff-mm", "100:120"), "--standoff-mm is for --instrument sensor"),
    ],
)
def test_issue_35_plan_options_it_would_ignore_are_refused(
    capsys, planned, extra, needle
):
    before = snapshot(planned)
    args = [planned / a if a.endswith(".csv") else a for a in extra]
    res = run_kinecal(
        capsys, "plan", "--robot", ROBOT, "--out", planned / "q.csv", *args, *PLAN
    )
    failed_with(res, needle)
    assert snapshot(planned) == before


@pytest.mark.parametrize("text", ['{"noise_sigma_mm": "abc"}', "{bad", "{}"])
def test_issue_35_plan_add_with_a_damaged_report_beside_the_model(capsys, work, text):
    (work / "report.json").write_text(text)
    res = run_kinecal(
        capsys, "plan", "--model", work / "model.yaml", "--add", "3", "--out",
        work / "p.csv", "--n-candidates", "60", "--random-draws", "2", "-q",
    )  # fmt: skip
    failed_with(res, "report.json", "noise_sigma_mm", "--noise-mm")


@pytest.mark.parametrize(
    "args, needle",
    [
        (("calibrate", "train.csv", "--robot", ROBOT, "--out", "o", "--model",
          "kinematic", "--ntm-order", "3"), "--ntm-order is for --model ntm"),
        (("calibrate", "train.csv", "--robot", ROBOT, "--out", "o", "--model", "rfcm",
          "--stage2", "project"), "--stage2 is for --model ntm"),
        (("calibrate", "train.csv", "--robot", ROBOT, "--out", "o", "--model", "full",
          "--cv", "off", "--cv-groups", "j1_deg"), "--cv-groups is for --cv K"),
        (("calibrate", "train.csv", "--robot", ROBOT, "--out", "o", "--reject", "off",
          "--reject-z", "3"), "--reject-z is for --reject auto"),
        (("export-urdf", "model.yaml", "--out", "c.urdf", "--tool-link", "t"),
         "--tool-link is for --like"),
        (("export-urdf", "model.yaml", "--out", "c.urdf", "--targets", "train.csv"),
         "--targets is for --data"),
        (("export-urdf", "model.yaml", "--out", "r.yaml", "--format", "yaml-dh",
          "--coupling", "mimic"), "--coupling is for urdf"),
        (("compensate", "test.csv", "--model", "model.yaml", "--out", "c.csv",
          "--decimals", "3"), "--decimals is for program files"),
        (("compensate", "test.csv", "--model", "model.yaml", "--out", "c.csv",
          "--report", "r.csv"), "--report is for program files"),
        (("plan", "--robot", ROBOT, "--iso9283", "--out", "i.csv", "--criterion", "D"),
         "--criterion chooses calibration poses, not --iso9283"),
    ],
)  # fmt: skip
def test_issue_35_options_a_run_would_ignore_are_refused(capsys, work, args, needle):
    """Given on the command line but not used by this run: refused (they were ignored,
    exit 0), before any work."""
    before = snapshot(work)
    named = [work / a if "." in a and not a.startswith("-") else a for a in args]
    failed_with(run_kinecal(capsys, *named), needle)
    assert snapshot(work) == before


def test_issue_35_evaluate_refit_marker_warns_of_a_marker_in_one_row(capsys, work):
    cal = work / "cal"
    data = _with_column(work / "train.csv", work / "m.csv", "marker", "m2", "m1")
    res = run_kinecal(
        capsys, "calibrate", data, "--robot", ROBOT, "--out", cal, "--model",
        "kinematic", "--cv", "off", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    test = _with_column(work / "test.csv", work / "t.csv", "marker", "m2", "m1")
    res = run_kinecal(capsys, "evaluate", test, "--model", cal / "model.yaml")
    assert res.code == 0 and "one row only" not in res.err, str(res)  # no refit: fine
    res = run_kinecal(
        capsys, "evaluate", test, "--model", cal / "model.yaml", "--refit", "marker"
    )
    assert res.code == 0 and "marker 'm2' is seen in one row only" in res.err, str(res)


def test_issue_35_report_never_writes_over_the_folder_it_reads(capsys, work):
    cal = work / "cal"
    res = run_kinecal(
        capsys, "calibrate", work / "train.csv", "--robot", ROBOT, "--out", cal,
        "--model", "kinematic", "--cv", "off", "--no-report", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    shutil.copytree(cal, work / "cal2")
    res = run_kinecal(capsys, "report", "--compare", cal, work / "cal" / ".." / "cal")
    failed_with(res, "OLD_DIR and NEW_DIR are one folder")
    before = snapshot(cal)
    for name in ("report.json", "residuals.csv", "manifest.json"):
        res = run_kinecal(capsys, "report", cal, "--out", cal / name, "--force")
        failed_with(res, "is an input of this command", f"the {name} of")
        res = run_kinecal(
            capsys,
            "report",
            "--compare",
            work / "cal2",
            cal,
            "--out",
            cal / name,
            "--force",
        )
        failed_with(res, "is an input of this command")
    assert snapshot(cal) == before


def test_issue_35_an_input_noted_by_its_reader_is_named_once(tmp_path):
    from kinecal._outputs import note_input, output_transaction, refuse_input
    from kinecal.errors import DataError

    f = tmp_path / "m.yaml"
    f.write_text("x\n")
    with output_transaction(), pytest.raises(DataError) as err:
        note_input(f)
        refuse_input(f)
    assert str(err.value).count(str(f)) == 1, err.value
