"""The next session of a model calibrated on several: data of one of its sets scored
with the tool or the marker refitted (``evaluate --refit tool|marker|user,tool``).

The closed-form start fitted a user frame for every set of the model, and a set the data
do not hold failed it: "set 'A' has 0 rows; a user frame needs at least 3", exit 2, for
data that score with exit 0 without the refit. The refit now holds the data's sets only
(as a refit of the user frames already did)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.cli_contract import make_point_data, run_kinecal


@pytest.fixture(scope="module")
def two_sets(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("refit_one_session")
    pt = make_point_data(d)
    a = pt["train"].read_text().splitlines()
    b = pt["test"].read_text().splitlines()
    train = d / "two.csv"
    rows = [a[0] + ",set"] + [f"{r},A" for r in a[1:]] + [f"{r},B" for r in b[1:11]]
    train.write_text("\n".join(rows) + "\n")
    later = d / "later_B.csv"
    later.write_text("\n".join([b[0] + ",set"] + [f"{r},B" for r in b[11:]]) + "\n")
    return {"dir": d, "train": train, "later": later}


def _rms(text: str) -> float:
    return float(re.search(r"^RMS\s+([0-9.]+) mm", text, re.M).group(1))


def test_refit_tool_or_marker_on_data_of_one_of_the_models_sets(two_sets, capsys):
    d = two_sets["dir"]
    res = run_kinecal(
        capsys, "calibrate", two_sets["train"], "--robot", "fanuc-lrmate200id",
        "--model", "kinematic", "--cv", "off", "--out", d / "cal", "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    model = d / "cal" / "model.yaml"
    plain = run_kinecal(capsys, "evaluate", two_sets["later"], "--model", model, "-q")
    assert plain.code == 0, str(plain)
    for refit in ("tool", "marker", "user,tool"):
        res = run_kinecal(
            capsys, "evaluate", two_sets["later"], "--model", model, "--refit", refit
        )
        assert res.code == 0, (refit, str(res))
        assert "poses  10" in res.out and "has 0 rows" not in res.err
        # more freedom on the same rows: never worse than the model as it is
        assert _rms(res.out) <= _rms(plain.out) + 1e-4
