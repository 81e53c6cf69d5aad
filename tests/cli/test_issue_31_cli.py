"""Issue 31 at the command line: --cv prints the in-session and the new-region figures
by name, report.json keeps both, and evaluate / compensate warn for poses outside the
calibrated joint ranges, naming rows and joints."""

from __future__ import annotations

import json

import numpy as np
import pytest


@pytest.fixture
def run_cli(run_cli_here):
    """The commands in this process: these tests check what they compute and say."""
    return run_cli_here


def _rows(path):
    lines = path.read_text().splitlines()
    head = lines[0].split(",")
    j1 = head.index("j1_deg")
    return lines[0], lines[1:], np.array([float(r.split(",")[j1]) for r in lines[1:]])


def _joints(rows):
    return np.array([[float(v) for v in r.split(",")[:6]] for r in rows])


def test_cv_figures_and_extrapolation_warnings(run_cli, simulated_exp2, tmp_path):
    head, rows, j1 = _rows(simulated_exp2 / "train.csv")
    cut = np.quantile(j1, 0.7)
    train = tmp_path / "low_j1.csv"
    train.write_text(
        "\n".join([head] + [r for r, a in zip(rows, j1) if a <= cut]) + "\n"
    )
    out = tmp_path / "cal"
    res = run_cli(
        "calibrate",
        str(train),
        "--robot",
        "fanuc-lrmate200id",
        "--out",
        str(out),
        "--cv",
        "3",
        "--no-report",
    )
    assert res.returncode == 0, res.stderr
    assert "in-session (3-fold CV by pose" in res.stdout
    assert "new region (3-fold CV by region" in res.stdout
    assert "second session" in res.stdout
    summary = json.loads((out / "report.json").read_text())
    figs = summary["cross_validation"]["figures"]
    assert set(figs) == {"in-session", "new region"}
    sel = summary["model_selection"]
    chosen = next(c for c in sel["candidates"] if c["chosen"])
    # One path: auto's table and --cv agree on the same (region) folds.
    assert sel["fold_unit"] == "region"
    assert figs["new region"]["model"]["rms_mm"] == chosen["cv_rms_mm"]
    # Poses beyond the calibrated J1 range: evaluate warns and still scores them.
    thead, trows, tj1 = _rows(simulated_exp2 / "test.csv")
    far = [r for r, a in zip(trows, tj1) if a > cut + 10][:40]
    kept = [r for r, a in zip(rows, j1) if a <= cut]
    lo, hi = _joints(kept).min(axis=0), _joints(kept).max(axis=0)
    inside = np.all((_joints(trows) > lo) & (_joints(trows) < hi), axis=1)
    near = [r for r, ok in zip(trows, inside) if ok][:40]
    assert len(near) >= 10
    (tmp_path / "far.csv").write_text("\n".join([thead, *far]) + "\n")
    (tmp_path / "near.csv").write_text("\n".join([thead, *near]) + "\n")
    res = run_cli(
        "evaluate",
        str(tmp_path / "far.csv"),
        "--model",
        str(out / "model.yaml"),
        "--json",
    )
    assert res.returncode == 0, res.stderr
    assert "outside the joint ranges the model was calibrated on" in res.stderr
    assert "line 2 (row 1) J1" in res.stderr, res.stderr
    assert json.loads(res.stdout)["n"] == len(far)
    res = run_cli(
        "evaluate",
        str(tmp_path / "near.csv"),
        "--model",
        str(out / "model.yaml"),
        "--json",
    )
    assert res.returncode == 0 and "outside the joint ranges" not in res.stderr
    res = run_cli(
        "compensate",
        str(tmp_path / "far.csv"),
        "--model",
        str(out / "model.yaml"),
        "--out",
        str(tmp_path / "corrected.csv"),
    )
    assert "outside the joint ranges the model was calibrated on" in res.stderr
    assert "Traceback" not in res.stderr
