"""Audit 4: inputs that parse but cannot be right, refused with the file, the place and
the value expected (exit 2), never accepted with a silently wrong result.

Each test damages a file kinecal wrote itself (tests/cli_contract.make_point_data) the
way a hand edit, a unit mix-up or a truncated copy does, runs the command as a user
does (in-process) and checks the one ``Error:`` line and that nothing was written.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from kinecal import _yaml as yaml
from tests.cli_contract import failed_with, make_point_data, run_kinecal


@pytest.fixture(scope="module")
def pt(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    return make_point_data(tmp_path_factory.mktemp("audit4"))


def _edited_model(pt: dict[str, Path], tmp_path: Path, edit) -> Path:
    doc = yaml.load(pt["model"].read_text())
    edit(doc)
    out = tmp_path / "edited.yaml"
    out.write_text(yaml.dump(doc))
    return out


@pytest.mark.parametrize(
    ("edit", "needles"),
    [
        (
            lambda d: d["info"].__setitem__("calibrated_joint_range", [[1.0, 2.0]]),
            ("info.calibrated_joint_range", "expected 6 pairs"),
        ),
        (
            lambda d: d["info"].__setitem__(
                "calibrated_joint_range",
                [[hi, lo] for lo, hi in d["info"]["calibrated_joint_range"]],
            ),
            ("info.calibrated_joint_range[0] (J1)", "lo <= hi"),
        ),
        (
            lambda d: d["info"].__setitem__("calibrated_joint_range", "all"),
            ("info.calibrated_joint_range", "pairs"),
        ),
        (lambda d: d["info"].__setitem__("kind", "laser"), ("info.kind", "point, pose")),
        (lambda d: d["info"].__setitem__("kind", "sensor"), ("info.kind", "'point'")),
        (lambda d: d["info"].__setitem__("n", "many"), ("info.n", "positive integer")),
    ],
)
def test_damaged_info_block_is_refused(pt, tmp_path, capsys, edit, needles) -> None:
    """The info block decides the extrapolation warnings and which data evaluate
    accepts: a damaged one was read silently (no warning, or 'calibrated 42 .. -33')."""
    m = _edited_model(pt, tmp_path, edit)
    out = tmp_path / "c.csv"
    for args in (
        ("evaluate", pt["test"], "--model", m, "--json"),
        ("compensate", pt["targets"], "--model", m, "--out", out, "-q"),
        ("fk", "--model", m, "--", "0", "0", "0", "0", "-90", "0"),
    ):
        failed_with(run_kinecal(capsys, *args), str(m), *needles)
    assert not out.exists()


def _with_columns(src: Path, dst: Path, names: str, values: str) -> Path:
    lines = src.read_text().splitlines()
    dst.write_text(
        "\n".join([f"{lines[0]},{names}", *(f"{ln},{values}" for ln in lines[1:])]) + "\n"
    )
    return dst


@pytest.mark.parametrize("columns", ["qw,qx,qy,qz", "w_deg,p_deg,r_deg"])
def test_constant_orientation_of_turning_poses_is_refused(
    pt, tmp_path, capsys, columns
) -> None:
    """The same orientation on every row while the robot turns the tool (a placeholder
    quaternion): the calibration ran and wrote a model fitted to it."""
    value = "1,0,0,0" if columns.startswith("q") else "0,0,0"
    data = _with_columns(pt["train"], tmp_path / "pose.csv", columns, value)
    out = tmp_path / "cal"
    res = run_kinecal(
        capsys, "calibrate", data, "--robot", "fanuc-lrmate200id", "--model",
        "kinematic", "--cv", "off", "--out", out, "-q",
    )
    failed_with(res, str(data), columns.replace(",", ", "), "turns the tool")
    assert not out.exists()
