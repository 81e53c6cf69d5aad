"""Second fault audit (``kinecal compare``): a TEST set that cannot score the models
(TRAIN itself, or another frame or robot) printed as a held-out table with exit 0."""

from __future__ import annotations

import shutil

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return make_point_data(tmp_path_factory.mktemp("compare"))


def _compare(capsys, train, test):
    return run_kinecal(
        capsys, "compare", train, test, "--robot", "fanuc-lrmate200id", "--models",
        "kinematic", "--json", "-q",
    )  # fmt: skip


def test_compare_refuses_train_as_test(capsys, tmp_path, data):
    copy = shutil.copy(data["train"], tmp_path / "copy.csv")
    failed_with(_compare(capsys, data["train"], copy), "copy.csv", "same rows as TRAIN")


def test_compare_refuses_a_test_set_in_another_frame(capsys, tmp_path, data):
    """The test rows 2 m away: every model 'off by' 2000 mm, printed with exit 0
    (evaluate refuses such data)."""
    lines = data["test"].read_text().splitlines()
    h = lines[0].split(",")
    ix = h.index("x_mm")
    out = [lines[0]]
    for ln in lines[1:]:
        v = ln.split(",")
        v[ix] = f"{float(v[ix]) + 2000:.6f}"
        out.append(",".join(v))
    moved = tmp_path / "moved.csv"
    moved.write_text("\n".join(out) + "\n")
    res = _compare(capsys, data["train"], moved)
    failed_with(res, "moved.csv", "expected at most 50 mm", "--refit user")
    assert _compare(capsys, data["train"], data["test"]).code == 0


def test_compare_refuses_a_model_given_twice(capsys, data):
    """--models kinematic,kinematic fitted it twice and listed two equal rows."""
    res = run_kinecal(
        capsys, "compare", data["train"], data["test"], "--robot",
        "fanuc-lrmate200id", "--models", "kinematic,kinematic", "--json", "-q",
    )  # fmt: skip
    failed_with(res, "--models", "'kinematic' given twice")
