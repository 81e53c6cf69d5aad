"""Second fault audit (``kinecal plan``, ``simulate``, ``import-urdf``): option values
that parse but say two things, or name what is not there. In-process."""

from __future__ import annotations

from tests.cli_contract import failed_with, run_kinecal


def test_plan_refuses_two_ranges_of_one_joint(capsys, tmp_path):
    """J1:-10:10,j1:0:20 planned with the last range, the first dropped unsaid."""
    out = tmp_path / "plan.csv"
    res = run_kinecal(
        capsys, "plan", "--robot", "fanuc-lrmate200id", "--poses", "30", "--out", out,
        "--n-candidates", "200", "--random-draws", "1", "--model", "kinematic",
        "--joint-range", "J1:-10:10,j1:0:20",
    )  # fmt: skip
    failed_with(res, "--joint-range", "each joint once", "j1:0:20")
    assert not out.exists()
