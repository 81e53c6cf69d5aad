"""Frames and Cartesian targets that cannot be right (issue 34 with issue 35's rule):
a user frame, tool or target beyond any robot's reach (wrong units, a damaged number:
1e308 mm ended in an overflow inside the inverse kinematics) or not finite is refused
with the file, line or option and what is expected; exit 2, nothing written."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tests.compensation.test_issue_34_cartesian import (
    FRAME_ARGS,
    WRITERS,
    _targets,
    _taught,
)


def _program(tracker_twin, tmp_path):
    cal = tracker_twin.calibrated
    q = _taught(np.random.default_rng(5), 2)
    writer, ext = WRITERS["fanuc-ls"]
    src = tmp_path / f"p{ext}"
    src.write_bytes(writer(cal, q, _targets(cal, q)).encode())
    return src


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (("--uframe", "1=1e308,0,0,0,0,0"), "is no pose; expected X, Y, Z [mm]"),
        (("--uframe", "1=2e5,0,0,0,0,0"), "expected mm and a frame within 100 m"),
        (
            ("--utool", "1=0,0,9000,0,0,0"),
            "9 m away; expected mm and a tool within 5 m",
        ),
        (("X", "5e5"), "(P[1]): the target lies 500 m from its origin"),
        (("X", "1e308"), "(P[1]): [1e+308, "),
        (("X", "1e400"), "(P[1]): [inf, "),
        (("--utool", "1=0,0,100,900,0,0"), "angle 900 deg; expected the three angles"),
        (("--uframe", "1=0,0,0,0,-400,0"), "angle -400 deg; expected the three angles"),
    ],
)
def test_far_or_infinite_frames_and_targets_refused(
    tracker_twin, model_file, run_cli, tmp_path, change, says
):
    src = _program(tracker_twin, tmp_path)
    args = FRAME_ARGS["fanuc-ls"]()
    if change[0].startswith("--"):
        args += list(change)  # given after the good one: it replaces it
    else:
        text = src.read_text()  # the first P[]'s X replaced
        src.write_text(re.sub(r"X =\s*-?[\d.]+", f"X = {change[1]}", text, count=1))
    out = tmp_path / "out.ls"
    res = run_cli(
        "compensate", src, "--model", model_file, "--out", out, *args,
        "--allow-unreachable",
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert says in res.stderr.strip().splitlines()[-1], res.stderr
    assert not out.exists()


def test_a_frames_file_in_a_folder_named_tools_keeps_the_frame_limit(
    tracker_twin, model_file, run_cli, tmp_path
):
    """The tool limit follows the frame kind, not the file's path."""
    src = _program(tracker_twin, tmp_path)
    d = tmp_path / "tools"
    d.mkdir()
    uf, ut = (a.split("=", 1)[1] for a in FRAME_ARGS["fanuc-ls"]()[1::2])
    far = "6000," + uf.split(",", 1)[1]  # a user frame 6 m out: a big cell, allowed
    (d / "frames.yaml").write_text(f"uframe:\n  1: [{far}]\nutool:\n  1: [{ut}]\n")
    res = run_cli(
        "compensate", src, "--model", model_file, "--out", tmp_path / "o.ls",
        "--frames", d / "frames.yaml", "--allow-unreachable",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr


def test_a_frames_file_not_in_utf8_names_the_byte(
    tracker_twin, model_file, run_cli, tmp_path
):
    src = _program(tracker_twin, tmp_path)
    uf, ut = (a.split("=", 1)[1] for a in FRAME_ARGS["fanuc-ls"]()[1::2])
    text = f"# r\u00e9glage\nuframe:\n  1: [{uf}]\nutool:\n  1: [{ut}]\n"
    (tmp_path / "frames.yaml").write_bytes(text.encode("latin-1"))
    res = run_cli(
        "compensate", src, "--model", model_file, "--out", tmp_path / "o.ls",
        "--frames", tmp_path / "frames.yaml",
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert "line 1: byte 0xe9 is not UTF-8" in res.stderr, res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "o.ls").exists()
