"""Audit 6: the next session with the user's own robot, as a metrology engineer runs it
(in-process): data of several sets, --cv-groups, a sequential plan from the data of
another calibration, fk beyond the calibrated ranges, a plan file with --n-train, a
robot with continuous joints, and sensor simulate-scan --every."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal
from tests.helpers import plan_lr_mate

_URDF = Path(__file__).parents[1] / "data" / "vendor_urdf"


@pytest.fixture(scope="module")
def pt(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_point_data(tmp_path_factory.mktemp("audit6"))


def _with_column(src: Path, dst: Path, name: str, value) -> Path:
    """``src`` with a column ``name``, ``value(k)`` on data row k."""
    lines = src.read_text().splitlines()
    out = [f"{lines[0]},{name}"] + [
        f"{ln},{value(k)}" for k, ln in enumerate(lines[1:])
    ]
    dst.write_text("\n".join(out) + "\n")
    return dst


def _calibrate(capsys, data: Path, out: Path, *more: str):
    return run_kinecal(
        capsys, "calibrate", data, "--robot", "fanuc-lrmate200id", "--model",
        "kinematic", "--out", out, "-q", *more,
    )  # fmt: skip


def test_cv_groups_with_empty_labels_is_refused(pt, capsys, tmp_path):
    """Rows with an empty --cv-groups cell were folded as a group of their own (and a
    column empty throughout as one group), unsaid."""
    data = _with_column(
        pt["train"], tmp_path / "g.csv", "rig", lambda k: "" if k % 7 == 3 else k % 5
    )
    res = _calibrate(capsys, data, tmp_path / "cal", "--cv-groups", "rig")
    failed_with(res, "g.csv", "line 5, column 'rig'", "empty", "group label")
    assert not (tmp_path / "cal").exists()
    full = _with_column(pt["train"], tmp_path / "f.csv", "rig", lambda k: k % 5)
    assert _calibrate(capsys, full, tmp_path / "ok", "--cv-groups", "rig").code == 0


def _two_sets(pt, tmp_path: Path, n_b: int) -> Path:
    """The training data as set A plus the first ``n_b`` test rows as set B."""
    a = pt["train"].read_text().splitlines()
    b = pt["test"].read_text().splitlines()[1 : 1 + n_b]
    text = [a[0] + ",set"] + [f"{r},A" for r in a[1:]] + [f"{r},B" for r in b]
    f = tmp_path / "two.csv"
    f.write_text("\n".join(text) + "\n")
    return f


def test_default_cv_that_empties_a_set_is_skipped_not_fatal(pt, capsys, tmp_path):
    """A set of 3 rows: the default 5-fold in-session cross-validation held one of
    them out and the whole calibration failed ('a fold's calibration failed: set 'B'
    has 2 rows', exit 2) after it had run; an explicit --cv 5 is refused before."""
    data = _two_sets(pt, tmp_path, 3)
    res = _calibrate(capsys, data, tmp_path / "cal")
    assert res.code == 0, str(res)
    assert "no cross-validation" in res.err and "set 'B'" in res.err
    res = _calibrate(capsys, data, tmp_path / "cal2", "--cv", "5")
    failed_with(res, "two.csv", "--cv 5", "set 'B'", "at least 3", "--cv off")
    assert not (tmp_path / "cal2").exists()


def test_fk_of_a_model_beyond_its_calibrated_ranges_warns(pt, capsys):
    """fk --model at J1 100 deg of a model calibrated on J1 -31 .. 40 deg printed the
    pose as a calibrated one (evaluate and compensate warn of the extrapolation)."""
    res = run_kinecal(
        capsys, "fk", "--model", pt["model"], "--json", "--", "100", "20", "-30", "40",
        "50", "60",
    )  # fmt: skip
    assert res.code == 0, str(res)
    warned = [ln for ln in res.err.splitlines() if ln.startswith("warning")]
    assert len(warned) == 1 and "J1 100.0 deg (calibrated" in warned[0], str(res)
    assert "extrapolates" in warned[0] and "experiment 2" in warned[0]
    inside = run_kinecal(
        capsys, "fk", "--model", pt["model"], "--json", "--", "5", "20", "-30", "0",
        "-50", "60",
    )  # fmt: skip
    assert inside.code == 0 and "warning" not in inside.err, str(inside)


def _plan_add(capsys, model: Path, data: Path, out: Path):
    return run_kinecal(
        capsys, "plan", "--add", "5", "--model", model, "--data", data, "--out", out,
        "--n-candidates", "200", "--random-draws", "1",
    )  # fmt: skip


def test_plan_add_refuses_data_of_a_set_the_model_lacks(pt, capsys, tmp_path):
    """--data with a set 'C' for a model of one set 'A'... of sets A and B: taken as the
    calibration's poses (within its joint ranges)."""
    data = _two_sets(pt, tmp_path, 10)
    assert _calibrate(capsys, data, tmp_path / "ab", "--cv", "off").code == 0
    model = tmp_path / "ab" / "model.yaml"
    other = _with_column(pt["train"], tmp_path / "c.csv", "set", lambda k: "C")
    res = _plan_add(capsys, model, other, tmp_path / "p.csv")
    failed_with(res, "c.csv", "set 'C' is not in the model", "--data")
    assert not (tmp_path / "p.csv").exists()
    assert _plan_add(capsys, model, data, tmp_path / "p2.csv").code == 0


def test_plan_add_refuses_measurements_the_model_does_not_fit(pt, capsys, tmp_path):
    """The data of another robot, frame or set-up whose joints lie within the model's
    calibrated ranges: planned from as the calibration's (evaluate refuses them)."""
    lines = pt["train"].read_text().splitlines()
    head = lines[0].split(",")
    ix = head.index("x_mm")
    moved = [lines[0]]
    for ln in lines[1:]:  # the points of another tracker station, 300 mm away
        v = ln.split(",")
        v[ix] = f"{float(v[ix]) + 300:.6f}"
        moved.append(",".join(v))
    other = tmp_path / "moved.csv"
    other.write_text("\n".join(moved) + "\n")
    res = _plan_add(capsys, pt["model"], other, tmp_path / "p.csv")
    failed_with(res, "moved.csv", "median error", "--data")
    assert not (tmp_path / "p.csv").exists()


def test_simulate_refuses_n_train_with_a_plan(capsys, tmp_path):
    """--plan P.csv --n-train 5: the plan's 20 poses were simulated, --n-train ignored
    unsaid. Refused: the plan's rows are the poses to calibrate (a plan is chosen as a
    whole; its first N rows are not what `plan --poses N` would choose)."""
    plan = tmp_path / "plan.csv"
    plan_lr_mate(capsys, plan)
    out = tmp_path / "sim"
    args = ["simulate", "--robot", "fanuc-lrmate200id", "--plan", plan, "--out", out]
    res = run_kinecal(capsys, *args, "--n-train", "5", "--n-test", "5", "-q")
    failed_with(res, "--n-train", "--plan", "remove it")
    assert not out.exists()
    res = run_kinecal(capsys, *args, "--n-test", "5", "-q")
    assert res.code == 0, str(res)
    assert (out / "train.csv").read_text().count("\n") == 21


def test_plan_for_a_robot_with_continuous_joints(capsys, tmp_path):
    """A URDF with continuous joints (no limits): plan drew candidates over infinite
    ranges and failed with an internal error (SVD did not converge, exit 1)."""
    out = tmp_path / "plan.csv"
    res = run_kinecal(
        capsys, "plan", "--robot", _URDF / "kinova_gen3_7dof.urdf", "--poses", "30",
        "--out", out, "--n-candidates", "300", "--random-draws", "1", "--model",
        "kinematic",
    )  # fmt: skip
    assert res.code == 0, str(res)
    rows = out.read_text().splitlines()
    assert len(rows) == 31 and rows[0].startswith("j1_deg")
    assert "nan" not in out.read_text()


def test_simulate_scan_every_names_the_option(capsys, tmp_path):
    """--every 1000 (1 of 120 planes) was refused as 'Invalid value for --center-mm'."""
    out = tmp_path / "scan"
    res = run_kinecal(
        capsys, "sensor", "simulate-scan", "--every", "1000", "--out", out
    )
    last = failed_with(res, "Invalid value for --every", "smaller --every")
    assert "--center-mm" not in last
    res = run_kinecal(
        capsys, "sensor", "simulate-scan", "--center-mm", "0,0,-5", "--out", out
    )
    failed_with(res, "Invalid value for --center-mm")


def test_evaluate_on_the_calibration_data_says_so(pt, capsys, tmp_path):
    """evaluate of the very file a model was calibrated on printed its training errors
    as held-out figures, unsaid (the next session's data file mixed up with the last
    one's)."""
    cal = tmp_path / "cal"
    assert _calibrate(capsys, pt["train"], cal, "--cv", "off").code == 0
    res = run_kinecal(capsys, "evaluate", pt["train"], "--model", cal / "model.yaml")
    assert res.code == 0, str(res)
    assert "the very data" in res.err and "training errors" in res.err, str(res)
    res = run_kinecal(capsys, "evaluate", pt["test"], "--model", cal / "model.yaml")
    assert res.code == 0 and "the very data" not in res.err, str(res)
