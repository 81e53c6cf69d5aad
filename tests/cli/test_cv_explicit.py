"""``--cv K`` given explicitly is checked on the data even when K is the default's: with
one value of the ``--cv-groups`` column, ``--cv 5`` is refused as ``--cv 4`` is, where the
default (no --cv) only notes that there is no cross-validation (found by audit5: the
option's text was compared with the default's)."""

from __future__ import annotations

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal


@pytest.fixture(scope="module")
def grouped(tmp_path_factory):
    d = tmp_path_factory.mktemp("cvgroups")
    pt = make_point_data(d)
    lines = pt["train"].read_text().splitlines()
    f = d / "grouped.csv"
    f.write_text(
        "\n".join([lines[0] + ",grp"] + [ln + ",g" for ln in lines[1:]]) + "\n"
    )
    return f


def _calibrate(capsys, data, out, *extra):
    return run_kinecal(
        capsys, "calibrate", data, "--robot", "fanuc-lrmate200id", "--model",
        "kinematic", "--cv-groups", "grp", "--out", out, "-q", *extra,
    )  # fmt: skip


@pytest.mark.parametrize("k", ["5", "4"])
def test_explicit_cv_that_the_groups_cannot_give_is_refused(
    grouped, tmp_path, capsys, k
):
    res = _calibrate(capsys, grouped, tmp_path / "out", "--cv", k)
    failed_with(res, str(grouped), f"{k}-fold", "values of column 'grp'")
    assert not (tmp_path / "out").exists()


def test_default_cv_that_the_groups_cannot_give_is_a_note(grouped, tmp_path, capsys):
    res = _calibrate(capsys, grouped, tmp_path / "out")
    assert res.code == 0, str(res)
    assert "no cross-validation" in res.err
