"""``kinecal report DIR`` and the report of ``kinecal calibrate`` (issues 21, 26): the
report is a function of the result folder's files, drawn without matplotlib."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from kinecal.io import measurements_to_csv
from kinecal.simulation import LaserTracker, experiment2


@pytest.fixture(scope="module")
def result_dir(tmp_path_factory):
    """A `kinecal calibrate --cv 3` result folder (100 simulated tracker poses)."""
    d = tmp_path_factory.mktemp("cal")
    exp = experiment2(7, tracker=LaserTracker(5e-6, 0.0), n_side=5)
    data = d / "train.csv"
    data.write_text(measurements_to_csv(exp.train, exp.truth.robot))
    out = d / "out"
    args = ["calibrate", str(data), "--robot", "fanuc-lrmate200id", "--model", "full"]
    args += ["--out", str(out), "--cv", "3", "--jobs", "1"]
    res = subprocess.run(
        [sys.executable, "-m", "kinecal", *args],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    return out, res


def _without_stamp(html: str) -> str:
    return re.sub(r"kinecal [^,<]+, \d{4}-\d\d-\d\d \d\d:\d\d", "", html)


def test_issue_21_calibrate_lists_every_file_it_wrote(result_dir):
    out, res = result_dir
    files = (
        "model.yaml",
        "report.json",
        "residuals.csv",
        "manifest.json",
        "report.html",
    )
    wrote = next(line for line in res.stdout.splitlines() if line.startswith("wrote"))
    for name in files:
        assert (out / name).is_file(), name
        assert name in wrote, wrote
    assert "report: wrote" in res.stderr  # progress line once the report is written


def test_issue_26_report_redraws_the_same_page_from_the_folder(result_dir, run_cli):
    out, _ = result_dir
    again = out.parent / "again.html"
    res = run_cli("report", str(out), "--out", str(again), "-q")
    assert res.returncode == 0, res.stderr
    assert str(again) in res.stdout
    assert _without_stamp(again.read_text()) == _without_stamp(
        (out / "report.html").read_text()
    )


def test_issue_26_report_refuses_to_overwrite_without_force(result_dir, run_cli):
    out, _ = result_dir
    res = run_cli("report", str(out), "-q")
    assert res.returncode == 2 and "use --force" in res.stderr
    assert run_cli("report", str(out), "-q", "--force").returncode == 0


def test_issue_26_held_out_accuracy_in_the_report(result_dir):
    out, _ = result_dir
    summary = json.loads((out / "report.json").read_text())
    cv = summary["cross_validation"]
    assert len(cv["model"]["rms_xyz_mm"]) == 3
    # pooled per-axis RMS squares add up to the pooled 3-D RMS square
    assert sum(v * v for v in cv["model"]["rms_xyz_mm"]) == pytest.approx(
        cv["model"]["rms_mm"] ** 2, rel=1e-9
    )
    html = (out / "report.html").read_text()
    # Issue 31: the in-session and the new-region figures, named apart.
    assert set(cv["figures"]) == {"in-session", "new region"}
    for name in ("in-session", "new region"):
        assert f"held-out, 3-fold cross-validation, {name}: this model" in html
        assert f"Cross-validation, {name} (3 folds)" in html
        assert f"held-out ({name})" in html  # in the per-axis RMS figure
    assert "second session" in html  # one session: what it cannot tell


def test_issue_26_report_needs_no_matplotlib(result_dir, tmp_path):
    out, _ = result_dir
    code = (
        "import sys\n"
        "from kinecal.cli import main\n"
        f"rc = main(['report', {str(out)!r}, '--out', {str(tmp_path / 'r.html')!r}, '-q'])\n"
        "print(rc, 'matplotlib' in sys.modules, 'numpy.ma' in sys.modules)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    # nor numpy.ma (25-40 ms to import; np.unique, np.median, np.percentile import it)
    assert res.stdout.split()[-3:] == ["0", "False", "False"], res.stderr


def test_issue_26_report_without_residuals_and_with_bad_ones(
    result_dir, run_cli, tmp_path
):
    out, _ = result_dir
    d = tmp_path / "copy"
    d.mkdir()
    for name in ("model.yaml", "report.json"):
        (d / name).write_bytes((out / name).read_bytes())
    res = run_cli("report", str(d), "-q")
    assert res.returncode == 0, res.stderr
    assert "no per-pose figures" in (d / "report.html").read_text()
    lines = (out / "residuals.csv").read_text().splitlines()
    cells = lines[3].split(",")
    cells[-1] = "abc"
    lines[3] = ",".join(cells)
    (d / "residuals.csv").write_text("\n".join(lines) + "\n")
    res = run_cli("report", str(d), "-q", "--force")
    assert res.returncode == 2
    assert "residuals.csv" in res.stderr and "Traceback" not in res.stderr
    (d / "residuals.csv").write_text(lines[0].replace("ex_mm", "e_mm") + "\n")
    res = run_cli("report", str(d), "-q", "--force")
    assert res.returncode == 2 and "column 'ex_mm'" in res.stderr


def test_issue_26_residuals_csv_matches_evaluate(result_dir, run_cli, tmp_path):
    out, _ = result_dir
    errs = tmp_path / "errors.csv"
    res = run_cli(
        "evaluate",
        str(out.parent / "train.csv"),
        "--model",
        str(out / "model.yaml"),
        "--errors-out",
        str(errs),
    )
    assert res.returncode == 0, res.stderr
    ev = np.loadtxt(errs, delimiter=",", skiprows=1, ndmin=2)
    head = (out / "residuals.csv").read_text().split("\n", 1)[0].split(",")
    rs = np.loadtxt(out / "residuals.csv", delimiter=",", skiprows=1, ndmin=2)
    cols = [head.index(c) for c in ("row", "ex_mm", "ey_mm", "ez_mm", "err_mm")]
    np.testing.assert_allclose(rs[:, cols], ev, atol=2e-6)


def test_issue_36_large_run_figures_from_a_sample_tables_from_all(
    result_dir, tmp_path, monkeypatch
):
    """A run with more poses than FIGURE_POSES: the per-pose figures get a deterministic
    sample (a subset of the rows, the largest error among them), the accuracy table the
    statistics of every pose."""
    from kinecal.report import _calibration, _poses, write_report

    out, _ = result_dir
    full = _poses.read_pose_errors(out / "residuals.csv")
    n_fig = 30
    assert full.n > n_fig
    monkeypatch.setattr(_calibration, "FIGURE_POSES", n_fig)
    seen: dict[str, list[np.ndarray]] = {}
    for name in (
        "fig_errors_before_after",
        "fig_error_histogram",
        "fig_residuals_vs_joints",
        "fig_workspace",
    ):
        real = getattr(_calibration.F, name)

        def spy(*args, _real=real, _name=name, **kw):
            seen[_name] = [
                a if isinstance(a, dict) else np.asarray(a) for a in args[:2]
            ]
            return _real(*args, **kw)

        monkeypatch.setattr(_calibration.F, name, spy)
    html = write_report(out, out=tmp_path / "report.html").read_text()
    sample = full.sample(n_fig)
    assert sample.n == n_fig
    np.testing.assert_array_equal(full.sample(n_fig).row, sample.row)  # deterministic
    i = np.searchsorted(full.row, sample.row)
    np.testing.assert_array_equal(full.row[i], sample.row)  # a subset, in order
    np.testing.assert_array_equal(full.after_mm[i], sample.after_mm)
    err = np.linalg.norm(full.after_mm, axis=1)
    assert np.linalg.norm(sample.after_mm, axis=1).max() == err.max()
    # the figures drew the sample
    np.testing.assert_array_equal(
        seen["fig_errors_before_after"][1], np.linalg.norm(sample.after_mm, axis=1)
    )
    np.testing.assert_array_equal(seen["fig_residuals_vs_joints"][0], sample.q)
    np.testing.assert_array_equal(seen["fig_workspace"][0], sample.p_mm)
    hist = seen["fig_error_histogram"][0]  # a dict: every pose counted
    np.testing.assert_array_equal(hist["after"], err)
    assert f"show {n_fig} of the {full.n} poses" in html
    # the table: the statistics of all poses (residuals.csv holds 6 decimals)
    summary = json.loads((out / "report.json").read_text())
    after = summary["after"]
    assert after["n"] == full.n
    assert after["rms_mm"] == pytest.approx(np.sqrt(np.mean(err**2)), abs=2e-6)
    assert after["max_mm"] == pytest.approx(err.max(), abs=2e-6)
    from kinecal.report._format import num

    row = html[html.index("calibration data, after") :].split("</tr>")[0]
    assert num(after["rms_mm"]) in row and num(after["max_mm"]) in row
    # below the threshold: every pose drawn, no note
    monkeypatch.setattr(_calibration, "FIGURE_POSES", full.n)
    html = write_report(out, out=tmp_path / "all.html").read_text()
    assert "poses evenly spaced" not in html
    assert seen["fig_workspace"][0].shape[0] == full.n
