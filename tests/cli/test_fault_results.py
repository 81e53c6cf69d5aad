"""Issue 21: result folders never lie (staged and moved into place at the end, --force
replaces the whole earlier result, normal file modes), the one error path (I/O
failures, internal errors, Ctrl-C, SIGTERM, a closed pipe), progress on long runs, and
self-contained help.
"""

from __future__ import annotations

import errno
import json
import os
import re
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tests.cli_contract import (
    check_contract,
    leftovers,
    make_point_data,
    run_kinecal,
    snapshot,
)

ROBOT = "fanuc-lrmate200id"
ROOT = Path(__file__).resolve().parents[2]
RESULT = {"model.yaml", "report.json", "residuals.csv", "manifest.json"}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return make_point_data(tmp_path_factory.mktemp("fault-results"))


def _calibrate(capsys, data, out, *extra):
    return run_kinecal(
        capsys, "calibrate", "--cv", "off", data["train"], "--robot", ROBOT, "--model", "kinematic",
        "--out", out, "-q", *extra,
    )  # fmt: skip


# --- staged result folders -----------------------------------------------------------


def test_issue_21_force_replaces_the_whole_result(data, capsys, tmp_path):
    out = tmp_path / "cal"
    res = _calibrate(capsys, data, out)
    assert res.code == 0 and (out / "report.html").is_file(), str(res)
    listed = json.loads((out / "manifest.json").read_text())["files"]
    assert sorted(listed) == sorted(p.name for p in out.iterdir()), listed  # once each
    (out / "notes.txt").write_text("mine\n")  # a file of the user's: kept
    res = _calibrate(capsys, data, out, "--force", "--no-report")
    assert res.code == 0, str(res)
    names = {p.name for p in out.iterdir()}
    # The earlier run's report.html does not stay beside the new model.yaml.
    assert names == RESULT | {"notes.txt"}, names
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["files"]) == RESULT
    assert "wrote" in res.out and str(out) in res.out and ".kinecal-tmp" not in res.out
    assert not leftovers(tmp_path)


def test_issue_21_files_get_the_normal_mode(data, capsys, tmp_path):
    old = os.umask(0o022)
    try:
        from kinecal import _outputs

        _outputs._UMASK = None  # read again under this umask
        out = tmp_path / "cal"
        assert _calibrate(capsys, data, out).code == 0
        err = tmp_path / "errors.csv"
        res = run_kinecal(
            capsys, "evaluate", data["test"], "--model", out / "model.yaml",
            "--errors-out", err,
        )  # fmt: skip
        assert res.code == 0, str(res)
    finally:
        os.umask(old)
        _outputs._UMASK = None
    for p in [*out.iterdir(), err]:
        assert stat.S_IMODE(p.stat().st_mode) == 0o644, p
    assert stat.S_IMODE(out.stat().st_mode) == 0o755


def test_issue_21_images_and_file_groups_get_the_normal_mode(tmp_path):
    from kinecal import _outputs
    from kinecal.io import atomic_write_files, write_image

    old = os.umask(0o027)  # group may read, others nothing
    _outputs._UMASK = None
    try:
        img = np.zeros((4, 5), np.uint8)
        paths = [write_image(tmp_path / "a.png", img, sync=s) for s in (True,)]
        paths.append(write_image(tmp_path / "b.png", img, sync=False))
        paths += atomic_write_files({tmp_path / "c.csv": "x\n", tmp_path / "d": b"y"})
    finally:
        os.umask(old)
        _outputs._UMASK = None
    for p in paths:
        assert stat.S_IMODE(p.stat().st_mode) == 0o640, p


def test_issue_21_failure_during_the_run_keeps_the_earlier_result(
    data, capsys, tmp_path, monkeypatch
):
    """A crash while the report is drawn (after model.yaml was written): the earlier
    result stays whole, exit 1 with one line, nothing staged is left."""
    out = tmp_path / "cal"
    assert _calibrate(capsys, data, out).code == 0
    before = snapshot(out)
    from kinecal import report

    def boom(*a, **k):
        raise RuntimeError("simulated crash")

    monkeypatch.setattr(report, "write_report", boom)
    res = _calibrate(capsys, data, out, "--force")
    assert res.code == 1, str(res)
    last = res.err.strip().splitlines()[-1]
    assert last.startswith("Error: internal error (RuntimeError: simulated crash")
    assert "KINECAL_DEBUG=1" in last and "Traceback" not in res.err
    assert snapshot(out) == before
    new = tmp_path / "new"
    assert _calibrate(capsys, data, new).code == 1 and not new.exists()
    assert not leftovers(tmp_path)


def test_issue_21_debug_shows_the_traceback(data, capsys, tmp_path, monkeypatch):
    from kinecal import report

    monkeypatch.setattr(report, "write_report", lambda *a, **k: 1 / 0)
    monkeypatch.setenv("KINECAL_DEBUG", "1")
    res = _calibrate(capsys, data, tmp_path / "cal")
    assert res.code == 1 and "Traceback" in res.err and "ZeroDivisionError" in res.err


def _fail_writes(monkeypatch, code: int, after: int = 0) -> None:
    """Every file write after the first ``after`` fails with errno ``code``."""
    real = os.fsync
    calls = {"n": 0}

    def fsync(fd):
        calls["n"] += 1
        if calls["n"] > after:
            raise OSError(code, os.strerror(code))
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)


@pytest.mark.parametrize(
    ("code", "words"),
    [(errno.ENOSPC, "no space left"), (errno.EDQUOT, "quota"), (errno.EIO, "disk")],
)
def test_issue_21_full_disk(data, capsys, tmp_path, monkeypatch, code, words):
    out = tmp_path / "cal"
    assert _calibrate(capsys, data, out).code == 0
    before = snapshot(out)
    _fail_writes(
        monkeypatch, code, after=1
    )  # model.yaml is written, then the disk fills
    for target, extra in ((out, ["--force"]), (tmp_path / "new", [])):
        res = _calibrate(capsys, data, target, *extra)
        check_contract(res)
        assert res.code == 5, str(res)
        assert words in res.err.splitlines()[-1]
    assert snapshot(out) == before and not (tmp_path / "new").exists()
    assert not leftovers(tmp_path)


def test_issue_21_read_only_file_system(data, capsys, tmp_path, monkeypatch):
    real_mkdir = os.mkdir
    ro = tmp_path / "ro"

    def mkdir(path, *a, **k):
        if str(path).startswith(str(ro)):
            raise OSError(errno.EROFS, "Read-only file system", str(path))
        return real_mkdir(path, *a, **k)

    monkeypatch.setattr(os, "mkdir", mkdir)
    res = _calibrate(capsys, data, ro / "cal")
    check_contract(res)
    assert res.code == 5, str(res)
    last = res.err.splitlines()[-1]
    assert "read-only file system" in last and str(ro) in last
    assert ".kinecal-tmp" not in last  # the user's path, not kinecal's staging folder


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_issue_21_out_without_permission(data, capsys, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        res = _calibrate(capsys, data, locked / "cal")
        err = tmp_path / "errors.csv"
        err.write_text("x\n")
        err.chmod(0o444)
        res2 = run_kinecal(
            capsys, "evaluate", data["test"], "--model", data["model"],
            "--errors-out", locked / "e.csv",
        )  # fmt: skip
    finally:
        locked.chmod(0o755)
    for r in (res, res2):
        check_contract(r)
        assert r.code == 5 and "permission denied" in r.err, str(r)


def test_issue_21_errors_out_cannot_be_written(data, capsys, tmp_path, monkeypatch):
    _fail_writes(monkeypatch, errno.EROFS)
    res = run_kinecal(
        capsys, "evaluate", data["test"], "--model", data["model"],
        "--errors-out", tmp_path / "errors.csv",
    )  # fmt: skip
    check_contract(res)
    assert res.code == 5 and "errors.csv: read-only file system" in res.err, str(res)
    assert not list(tmp_path.iterdir())  # no temporary file left


def test_issue_21_errors_out_is_a_folder(data, capsys, tmp_path):
    res = run_kinecal(
        capsys, "evaluate", data["test"], "--model", data["model"],
        "--errors-out", tmp_path,
    )  # fmt: skip
    check_contract(res)
    assert res.code == 2 and "is a directory" in res.err, str(res)


def test_issue_21_staging_left_by_a_killed_run_is_swept(data, capsys, tmp_path):
    dead = tmp_path / ".cal.kinecal-tmp-999999999-abcd"  # no such process
    dead.mkdir()
    (dead / "model.yaml").write_text("half\n")
    assert _calibrate(capsys, data, tmp_path / "cal").code == 0
    assert not dead.exists()


def test_issue_21_simulate_and_compare_list_every_file(data, capsys, tmp_path):
    out = tmp_path / "cmp"
    res = run_kinecal(
        capsys, "compare", data["train"], data["test"], "--robot", ROBOT, "--models",
        "kinematic,ntm", "--out", out, "-q",
    )  # fmt: skip
    assert res.code == 0, str(res)
    names = {p.name for p in out.iterdir()}
    line = next(ln for ln in res.out.splitlines() if ln.startswith("wrote"))
    for n in names:
        assert n in line, (n, line)
    assert {"model-kinematic.yaml", "model-ntm.yaml", "report.html"} <= names
    # --force and fewer models: the earlier model-ntm.yaml goes with the earlier result
    res = run_kinecal(
        capsys, "compare", data["train"], data["test"], "--robot", ROBOT, "--models",
        "kinematic", "--out", out, "--force", "-q",
    )  # fmt: skip
    assert res.code == 0 and not (out / "model-ntm.yaml").exists(), str(res)


# --- progress --------------------------------------------------------------------------


@pytest.mark.slow  # (a calibration long enough to report its stages: 1.7 s)
def test_issue_21_long_stages_talk(capsys):
    from kinecal.cli._common import Progress

    say = Progress(quiet=False, heartbeat=0.2)
    try:
        say("stage 1", "fitting")
        time.sleep(0.75)
        say.begin("report", "drawing")  # no line unless it lasts
        time.sleep(0.1)
        err_short = capsys.readouterr().err
        time.sleep(0.5)
    finally:
        say.close()
    err = err_short + capsys.readouterr().err
    lines = err.splitlines()
    assert lines[0].endswith("stage 1: fitting")
    beats = [ln for ln in lines if "stage 1: still working" in ln]
    assert 2 <= len(beats) <= 4, lines
    assert "report" not in err_short
    assert any("report: drawing: still working" in ln for ln in lines), lines
    time.sleep(0.3)
    assert capsys.readouterr().err == ""  # closed: silent


# --- Ctrl-C, SIGTERM, a closed pipe (subprocesses) ------------------------------------


def _big_data(tmp_path: Path, data) -> Path:
    """A few thousand poses: each stage of the calibration lasts long enough to be hit."""
    lines = data["test"].read_text().splitlines()
    rng = np.random.default_rng(0)
    rows = []
    for _k in range(150):
        for ln in lines[1:]:
            v = np.array(ln.split(","), float)
            v[:6] += rng.normal(0, 1e-4, 6)  # distinct poses
            rows.append(",".join(f"{x:.6f}" for x in v))
    f = tmp_path / "big.csv"
    f.write_text("\n".join([lines[0], *rows]) + "\n")
    return f


def _default_signals() -> None:
    for s in (signal.SIGINT, signal.SIGTERM):
        signal.signal(s, signal.SIG_DFL)


def _interrupt(args: list[str], when: str, sig=signal.SIGINT, timeout=300, late=None):
    """Run kinecal, send ``sig`` to its process group when a stderr line holds
    ``when`` (as Ctrl-C does), return (exit code, stderr). ``late``: a list that gets
    True when the command had already ended as the line was read (a loaded machine
    reads the pipe late: the signal then reaches nothing), else False."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1"}
    p = subprocess.Popen(
        [sys.executable, "-m", "kinecal", *map(str, args)],
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        start_new_session=True,
        env=env,
        # A suite started as a background job hands its children Ctrl-C ignored (POSIX),
        # and Python keeps an ignored SIGINT ignored: give the command the default, as a
        # terminal would.
        preexec_fn=_default_signals,
    )
    assert p.stderr is not None
    seen = []
    t0 = time.monotonic()
    for line in p.stderr:
        seen.append(line)
        if when in line:
            if late is not None:
                late.append(p.poll() is not None)
            if p.returncode is None:  # (a reaped group is gone: nothing to signal)
                os.killpg(p.pid, sig)
            break
        assert time.monotonic() - t0 < timeout
    seen.append(p.stderr.read())
    p.wait(timeout=timeout)
    return p.returncode, "".join(seen)


STAGES = ["data:", "init:", "stage 1", "stage 3", "write:", "report:"]


def _full_fit(data, out) -> list:
    """The arguments of a full-model calibration of ``data`` into ``out`` (no CV): one
    that lasts long enough to be interrupted."""
    return ["calibrate", "--cv", "off", data, "--robot", ROBOT, "--model", "full",
            "--out", out]  # fmt: skip


def _ctrl_c_at(stage, data, tmp_path, capsys):
    big = _big_data(tmp_path, data)
    out = tmp_path / "cal"
    assert _calibrate(capsys, data, out).code == 0  # an earlier result
    before = snapshot(out)
    sent_late: list[bool] = []
    code, err = _interrupt([*_full_fit(big, out), "--force"], stage, late=sent_late)
    assert stage in err and "Traceback" not in err
    last = err.strip().splitlines()[-1]
    finished = code == 0 or (code == 3 and sent_late == [True])
    if finished or "after the results were written" in last:
        # The run finished, or was moving its results into place, before the signal
        # came: then the new result is whole. (A loaded CI runner once read the 'data:'
        # line from the pipe after the 2.7 s run had ended with exit 3, its results
        # flagged: these jittered copies of 20 poses may not converge.)
        assert RESULT <= {p.name for p in out.iterdir()} and not leftovers(tmp_path)
        return
    # 130; seen once in CI under load at the 'data:' stage: -2 (the process ended by
    # SIGINT after printing its message; not reproduced in 24 runs at idle; see the
    # stop note). Either way the message is said and nothing is left half-written.
    assert code in (130, -signal.SIGINT), err
    assert last.startswith("Error: interrupted (Ctrl-C)"), err
    assert "Traceback" not in err
    assert snapshot(out) == before
    assert not leftovers(tmp_path)


def test_issue_21_ctrl_c_during_the_fit(data, tmp_path, capsys):
    _ctrl_c_at("stage 1", data, tmp_path, capsys)


@pytest.mark.slow
@pytest.mark.parametrize("stage", STAGES)
def test_issue_21_ctrl_c_during_each_stage(data, tmp_path, capsys, stage):
    _ctrl_c_at(stage, data, tmp_path, capsys)


@pytest.mark.slow
def test_issue_21_ctrl_c_in_worker_processes(data, tmp_path, capsys):
    big = _big_data(tmp_path, data)
    args = ["calibrate", big, "--robot", ROBOT, "--model", "auto", "--jobs", "2"]
    code, err = _interrupt([*args, "--out", tmp_path / "cal"], "auto:")
    assert code == 130 and "Traceback" not in err, err
    assert not (tmp_path / "cal").exists() and not leftovers(tmp_path)


def test_issue_21_sigterm_removes_the_staged_result(data, tmp_path, capsys):
    big = _big_data(tmp_path, data)
    code, err = _interrupt(
        _full_fit(big, tmp_path / "cal"), "stage 1", sig=signal.SIGTERM
    )
    if code == 0:
        return  # finished first
    assert code == 143 and err.strip().splitlines()[-1].startswith("Error: terminated")
    assert not (tmp_path / "cal").exists() and not leftovers(tmp_path)


def test_issue_21_closed_pipe_is_quiet():
    p = subprocess.run(
        f"{sys.executable} -m kinecal robots | head -c 1",
        shell=True,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert "Traceback" not in p.stderr and "Error" not in p.stderr, p.stderr


# --- exit codes, messages and help ------------------------------------------------------


def test_issue_21_every_exit_code_is_documented():
    from kinecal.cli._errors import ExitCode

    doc = (ROOT / "docs" / "errors.md").read_text()
    table = {int(m) for m in re.findall(r"^\| *`?(\d+)`? *\|", doc, flags=re.M)}
    assert table == {int(c) for c in ExitCode}, table
    readme = (ROOT / "README.md").read_text()
    assert "docs/errors.md" in readme


def test_issue_21_no_command_shows_the_help(capsys):
    for args in ([], ["sensor"]):
        res = run_kinecal(capsys, *args)
        assert res.code == 0 and res.out.startswith("Usage: kinecal") and not res.err


def test_issue_21_usage_errors_are_one_line(capsys):
    for args in (["frob"], ["calibrate"], ["fk", "--robot", ROBOT, "--frob"]):
        res = run_kinecal(capsys, *args)
        check_contract(res)
        assert res.code == 2 and len(res.err.strip().splitlines()) == 1, str(res)
        assert "--help" in res.err


def _commands():
    from kinecal.cli import cli

    out = [[]]
    for name, cmd in cli.commands.items():
        out.append([name])
        for sub in getattr(cmd, "commands", {}):
            out.append([name, sub])
    return out


def test_issue_21_help_is_self_contained(capsys):
    for cmd in _commands():
        res = run_kinecal(capsys, *cmd, "--help")
        assert res.code == 0, cmd
        assert "DESIGN" not in res.out and "§" not in res.out, (cmd, res.out)
    for page in (ROOT / "docs").glob("*.md"):
        text = page.read_text()
        assert "DESIGN" not in text, page  # a file users do not have
    readme = (ROOT / "README.md").read_text()
    assert "DESIGN" not in readme
