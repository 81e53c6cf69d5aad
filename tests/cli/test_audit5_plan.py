"""Second fault audit (``kinecal plan``, ``simulate``, ``import-urdf``): option values
that parse but say two things, or name what is not there. In-process."""

from __future__ import annotations

from tests.cli_contract import failed_with, run_kinecal
from tests.helpers import plan_lr_mate


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


def test_simulate_refuses_more_poses_than_any_session(capsys, tmp_path):
    """--n-train 10^8 was killed by the kernel for its memory (exit 137); 10^9 test
    poses ran out of memory (exit 5)."""
    out = tmp_path / "sim"
    res = run_kinecal(
        capsys, "simulate", "--robot", "fanuc-lrmate200id", "--out", out,
        "--n-train", "30", "--n-test", "1000000000", "-q",
    )  # fmt: skip
    failed_with(res, "--n-test 1000000000", "at most 1000000")
    assert not out.exists()


def test_simulate_refuses_a_payload_beyond_the_robot_naming_the_option(
    capsys, tmp_path
):
    """--payload-kg 1e6 was refused only when truth.yaml (an output) was written, and
    the message named that file instead of the option."""
    out = tmp_path / "sim"
    res = run_kinecal(
        capsys, "simulate", "--robot", "fanuc-lrmate200id", "--out", out,
        "--n-train", "30", "--n-test", "5", "--payload-kg", "1e6", "-q",
    )  # fmt: skip
    last = failed_with(res, "--payload-kg", "up to 70 kg")
    assert "truth.yaml" not in last
    assert not out.exists()


def test_a_plan_of_another_robot_is_refused(capsys, tmp_path):
    """simulate --robot ur5e --plan PLAN.csv of the LR Mate: simulated with exit 0 (the
    LR Mate's joints fit the UR5e's limits); PLAN.report.json names the robot."""
    plan = tmp_path / "plan.csv"
    plan_lr_mate(capsys, plan)
    out = tmp_path / "sim"
    res = run_kinecal(
        capsys, "simulate", "--robot", "ur5e", "--plan", plan, "--out", out,
        "--n-test", "5", "-q",
    )  # fmt: skip
    failed_with(res, "plan.csv", "planned for fanuc-lrmate200id", "ur5e")
    assert not out.exists()
    res = run_kinecal(
        capsys, "simulate", "--robot", "fanuc-lrmate200id", "--plan", plan, "--out",
        out, "--n-test", "5", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)


def test_plan_add_refuses_data_the_model_was_not_calibrated_on(capsys, tmp_path):
    """--data of other poses (J1 60 deg beyond the calibrated range) was taken as the
    calibration's information, the plan added to poses never measured."""
    from tests.cli_contract import make_point_data

    d = make_point_data(tmp_path)
    lines = d["train"].read_text().splitlines()
    moved = [lines[0]]
    for ln in lines[1:]:
        v = ln.split(",")
        v[0] = f"{float(v[0]) + 60:.6f}"
        moved.append(",".join(v))
    other = tmp_path / "other.csv"
    other.write_text("\n".join(moved) + "\n")

    def plan(data, out):
        return run_kinecal(
            capsys, "plan", "--add", "5", "--model", d["model"], "--data", data,
            "--out", out, "--n-candidates", "200", "--random-draws", "1",
        )  # fmt: skip

    res = plan(other, tmp_path / "p1.csv")
    failed_with(res, "other.csv", "line 2, column j1_deg", "calibrated on", "--data")
    assert not (tmp_path / "p1.csv").exists()
    assert plan(d["train"], tmp_path / "p2.csv").code == 0
