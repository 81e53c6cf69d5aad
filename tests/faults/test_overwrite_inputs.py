"""Issue 35 (3): an output never replaces an input of the same command, --force or not
(the same name, another spelling of it, a symbolic link); and (2) a result folder whose
files come from different runs is refused by ``kinecal report``."""

from __future__ import annotations

import os
import shutil

import pytest

from tests.cli_contract import failed_with, run_kinecal, snapshot

ROBOT = "fanuc-lrmate200id"


@pytest.fixture
def work(data, tmp_path):
    for k in ("train", "test", "model", "targets"):
        shutil.copy(data[k], tmp_path / data[k].name)
    return tmp_path


def _refused(capsys, work, *args):
    before = snapshot(work)
    res = run_kinecal(capsys, *args)
    failed_with(res, "is an input of this command", "--force or not")
    assert snapshot(work) == before  # nothing replaced, nothing left behind
    return res


def test_issue_35_compensate_out_onto_its_targets(capsys, work):
    _refused(
        capsys, work, "compensate", work / "targets.csv", "--model", work / "model.yaml",
        "--out", work / "targets.csv", "--force", "-q",
    )  # fmt: skip


def test_issue_35_compensate_out_onto_its_model_by_another_name(capsys, work):
    (work / "sub").mkdir()
    _refused(
        capsys, work, "compensate", work / "targets.csv", "--model", work / "model.yaml",
        "--out", work / "sub" / ".." / "model.yaml", "--force", "-q",
    )  # fmt: skip


def test_issue_35_evaluate_errors_out_onto_its_data(capsys, work):
    _refused(
        capsys, work, "evaluate", work / "test.csv", "--model", work / "model.yaml",
        "--errors-out", work / "test.csv", "--force", "-q",
    )  # fmt: skip


def test_issue_35_an_output_through_a_symbolic_link_to_the_input(capsys, work):
    os.symlink(work / "test.csv", work / "link.csv")
    _refused(
        capsys, work, "evaluate", work / "test.csv", "--model", work / "model.yaml",
        "--errors-out", work / "link.csv", "--force", "-q",
    )  # fmt: skip


def test_issue_35_export_urdf_onto_its_model(capsys, work):
    _refused(
        capsys, work, "export-urdf", work / "model.yaml", "--out", work / "model.yaml",
        "--force",
    )  # fmt: skip


def test_issue_35_calibrate_out_folder_holding_its_data_as_a_result_file(capsys, work):
    """The data is residuals.csv of the folder that --out --force would replace."""
    out = work / "cal"
    out.mkdir()
    shutil.copy(work / "train.csv", out / "residuals.csv")
    _refused(
        capsys, work, "calibrate", "--cv", "off", out / "residuals.csv", "--robot", ROBOT,
        "--model", "kinematic", "--out", out, "--force", "-q",
    )  # fmt: skip


def test_issue_35_report_out_onto_the_folders_model(capsys, data, tmp_path):
    out = tmp_path / "cal"
    res = run_kinecal(
        capsys, "calibrate", "--cv", "off", data["train"], "--robot", ROBOT, "--model", "kinematic",
        "--out", out, "-q",
    )  # fmt: skip
    assert res.code == 0, res
    _refused(capsys, tmp_path, "report", out, "--out", out / "model.yaml", "--force")


def test_issue_35_outputs_beside_inputs_still_work(capsys, work):
    res = run_kinecal(
        capsys, "evaluate", work / "test.csv", "--model", work / "model.yaml",
        "--errors-out", work / "errors.csv", "-q",
    )  # fmt: skip
    assert res.code == 0, res
    assert (work / "errors.csv").is_file()


def test_issue_35_report_refuses_files_of_different_runs(capsys, data, tmp_path):
    runs = []
    for name, model in (("a", "kinematic"), ("b", "full")):
        out = tmp_path / name
        res = run_kinecal(
            capsys, "calibrate", "--cv", "off", data["train"], "--robot", ROBOT, "--model", model,
            "--out", out, "-q",
        )  # fmt: skip
        assert res.code == 0, res
        runs.append(out)
    res = run_kinecal(capsys, "report", runs[0], "--force")
    assert res.code == 0, res  # a folder of one run draws
    shutil.copy(runs[1] / "model.yaml", runs[0] / "model.yaml")
    res = run_kinecal(capsys, "report", runs[0], "--force")
    failed_with(res, "model.yaml", "manifest.json", "different runs")


def test_issue_35_reconstruct_out_onto_one_of_its_images(capsys, tmp_path):
    from kinecal.cli import main

    d = tmp_path / "scan"
    assert main(["sensor", "simulate-scan", "--out", str(d), "--every", "40"]) == 0
    img = sorted(d.glob("plane_*.png"))[0]
    _refused(
        capsys, tmp_path, "sensor", "reconstruct", d, "--sensor", d / "sensor.yaml",
        "--out", img, "--force",
    )  # fmt: skip


def test_issue_35_without_force_the_message_does_not_suggest_force(capsys, work):
    res = _refused(
        capsys, work, "evaluate", work / "test.csv", "--model", work / "model.yaml",
        "--errors-out", work / "test.csv", "-q",
    )  # fmt: skip
    assert "use --force" not in res.err
