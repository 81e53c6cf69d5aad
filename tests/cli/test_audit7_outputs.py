"""Audit 7: output names that are not a plain new file. The atomic write (a temporary
file renamed over the target) replaced a symbolic link by a plain file (the file it
pointed to kept its old content) and a device or pipe by a plain file (as root:
``--out /dev/stdout --force`` replaced /dev/stdout); ``--out new/`` wrote a file
``new``."""

from __future__ import annotations

import os

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return make_point_data(tmp_path_factory.mktemp("audit7_out"))


def _compensate(capsys, data, out, *extra):
    return run_kinecal(
        capsys, "compensate", data["targets"], "--model", data["model"], "--out", out,
        *extra,
    )  # fmt: skip


def test_force_through_a_link_writes_the_file_it_points_to(capsys, data, tmp_path):
    shared = tmp_path / "shared"
    shared.mkdir()
    target = shared / "corrected.csv"
    target.write_text("old\n")
    link = tmp_path / "corrected.csv"
    link.symlink_to(target)
    res = _compensate(capsys, data, link, "--force")
    assert res.code == 0, str(res)
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text().startswith("x_mm,")  # was: still 'old'


def test_without_force_the_link_names_itself(capsys, data, tmp_path):
    target = tmp_path / "t.csv"
    target.write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    failed_with(_compensate(capsys, data, link), f"{link}: exists", "--force")
    assert target.read_text() == "old\n"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_pipe_is_refused_not_replaced(capsys, data, tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    res = _compensate(capsys, data, fifo, "--force")
    failed_with(res, str(fifo), "not a regular file", "device, pipe or socket")
    assert not fifo.is_file() and fifo.exists()  # still the pipe


def test_a_name_ending_in_a_slash_is_refused(capsys, data, tmp_path):
    out = f"{tmp_path / 'new'}/"
    failed_with(_compensate(capsys, data, out), out, "ends in '/'", "name of a file")
    assert not (tmp_path / "new").exists()


def test_a_result_folder_name_may_end_in_a_slash(capsys, data, tmp_path):
    out = f"{tmp_path / 'cal'}/"
    res = run_kinecal(
        capsys, "calibrate", data["train"], "--robot", "fanuc-lrmate200id",
        "--model", "kinematic", "--out", out, "--no-report",
    )  # fmt: skip
    assert res.code == 0, str(res)
    assert (tmp_path / "cal" / "model.yaml").is_file()
