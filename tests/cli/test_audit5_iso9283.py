"""Second fault audit (``kinecal evaluate --iso9283``): point labels that do not fit the
test's layout (P1 at the cube's centre) gave per-point figures of the wrong points with
exit 0. In-process, on the simulated cube test of tests/iso9283."""

from __future__ import annotations

import pytest

from tests.cli_contract import failed_with, run_kinecal
from tests.iso9283.test_evaluate import _write, case  # noqa: F401  (the fixture)


@pytest.mark.parametrize(("a", "b"), [("P1", "P2"), ("P2", "P3"), ("P1", "P5")])
def test_swapped_point_labels_are_refused(case, capsys, tmp_path, a, b):  # noqa: F811
    swap = {a: b, b: a}

    def edit(r):
        r[6] = swap.get(r[6], r[6])

    data = _write(case, tmp_path / "swapped.csv", edit=edit)
    res = run_kinecal(
        capsys, "evaluate", data, "--model", case["dir"] / "model.yaml", "--iso9283"
    )
    failed_with(res, "swapped.csv", "column 'iso_point'", "P1 at the cube's centre")


def test_the_plan_layout_is_accepted(case, capsys, tmp_path):  # noqa: F811
    data = _write(case, tmp_path / "ok.csv")
    res = run_kinecal(
        capsys, "evaluate", data, "--model", case["dir"] / "model.yaml", "--iso9283"
    )
    assert res.code == 0, str(res)
