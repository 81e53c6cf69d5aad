"""Issue 35 (7), the audit's system faults over every command that writes: a full disk
(every write failing with ENOSPC) during a --force rerun ends in exit 5 and one Error
line, the earlier output unchanged and nothing left behind; two runs writing one
output at once leave one complete result."""

from __future__ import annotations

import errno
import os
import shutil
import threading

import pytest

from tests.cli_contract import check_contract, leftovers, run_kinecal, snapshot

ROBOT = "fanuc-lrmate200id"

# (command, the output it writes) with {data}-style names; {out} in the work folder.
COMMANDS = {
    "evaluate": ["evaluate", "{test}", "--model", "{model}", "--errors-out", "{out}", "-q"],
    "compensate": ["compensate", "{targets}", "--model", "{model}", "--out", "{out}", "-q"],
    "export-urdf": ["export-urdf", "{model}", "--out", "{out}"],
    "export-dh": ["export-urdf", "{model}", "--format", "yaml-dh", "--out", "{out}"],
    "plan": [
        "plan", "--robot", ROBOT, "--model", "kinematic", "--poses", "12",
        "--n-candidates", "60", "--out", "{out}", "-q",
    ],
    "calibrate": [
        "calibrate", "--cv", "off", "{train}", "--robot", ROBOT, "--model", "kinematic",
        "--out", "{out}", "-q",
    ],
}  # fmt: skip


def _args(data, name, out):
    names = {**{k: str(v) for k, v in data.items()}, "out": str(out)}
    return [a.format(**names) for a in COMMANDS[name]]


def _full_disk(monkeypatch):
    def fsync(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(os, "fsync", fsync)


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_issue_35_full_disk_keeps_the_earlier_output(
    data, capsys, tmp_path, monkeypatch, name
):
    work = tmp_path / "w"
    work.mkdir()
    out = work / "result"
    res = run_kinecal(capsys, *_args(data, name, out))
    assert res.code == 0, res
    before = snapshot(work)
    _full_disk(monkeypatch)
    res = run_kinecal(capsys, *_args(data, name, out), "--force")
    check_contract(res)
    assert res.code == 5, res
    assert "no space left" in res.err.splitlines()[-1].lower(), res
    assert snapshot(work) == before
    assert not leftovers(work)


@pytest.mark.parametrize("name", ["compensate", "calibrate"])
def test_issue_35_two_runs_into_one_output(data, capsys, tmp_path, name):
    """Two threads writing the same output with --force: each ends in exit 0 or a
    one-line error, and the output is one run's complete result."""
    from kinecal.cli import main

    out = tmp_path / "result"
    codes: list[int] = []

    def run() -> None:
        codes.append(main([*_args(data, name, out), "--force"]))

    threads = [threading.Thread(target=run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert sorted(codes)[0] == 0 and all(c in (0, 2, 5) for c in codes), codes
    assert not leftovers(tmp_path)
    # the result reads back as a whole
    if name == "calibrate":
        res = run_kinecal(
            capsys, "evaluate", data["test"], "--model", out / "model.yaml"
        )
        assert res.code == 0, res
    else:
        assert out.read_text().count("\n") > 1
    shutil.rmtree(out, ignore_errors=True)
