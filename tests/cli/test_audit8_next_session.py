"""Audit 8: what a user hands back to kinecal in the next session (a plan measured on
the twin, new measurement files, model files), through the CLI in-process."""

from __future__ import annotations

import json

import pytest

from tests.cli_contract import run_kinecal


@pytest.mark.slow  # (an end-to-end run: plan, simulate, calibrate, ISO 9283)
def test_simulate_keeps_an_iso_plan_columns(capsys, tmp_path):
    """simulate --plan ISO.csv dropped iso_point/iso_cycle (and cmd_*): the simulated
    test could not go through evaluate --iso9283 ("no column 'iso_point'")."""
    plan, sim = tmp_path / "iso.csv", tmp_path / "sim"
    res = run_kinecal(
        capsys, "plan", "--iso9283", "--robot", "fanuc-lrmate200id", "--out", plan,
        "--cycles", "2", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    res = run_kinecal(
        capsys, "simulate", "--robot", "fanuc-lrmate200id", "--plan", plan,
        "--out", sim, "--n-test", "30", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    head, *rows = (sim / "train.csv").read_text().splitlines()
    want = plan.read_text().splitlines()
    cols = head.split(",")
    assert cols[-8:-6] == ["iso_point", "iso_cycle"], head
    assert cols[-6:] == [f"cmd_{c}" for c in "x_mm y_mm z_mm a_deg b_deg c_deg".split()]
    assert [r.split(",")[-8:] for r in rows] == [r.split(",")[6:] for r in want[1:]]
    res = run_kinecal(
        capsys, "evaluate", sim / "train.csv", "--model", sim / "truth.yaml",
        "--iso9283", "--json",
    )  # fmt: skip
    assert res.code == 0, str(res)
    iso = json.loads(res.out)["iso9283"]
    assert iso["cycles"] == {f"P{k}": 2 for k in range(1, 6)}
    # the truth's own figures: noise only, far below the nominal robot's
    assert iso["model"]["max_ap_mm"] < iso["nominal"]["max_ap_mm"] / 5
