"""docs/tutorial.md runs: every ``sh`` block's commands in order, in a fresh folder,
``kinecal`` in this process (the csv block before a ``compensate`` is its targets.csv).
The numbers the page quotes are checked loosely, so a change that breaks them shows."""

from __future__ import annotations

import json
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest

from kinecal.robot import robot_from_urdf
from tests.independent_arm import random_poses, true_arm, urdf_text

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "tutorial.md"


def _blocks(text: str) -> list[tuple[str, str]]:
    return re.findall(r"```(sh|csv|text)\n(.*?)```", text, flags=re.S)


@pytest.mark.slow  # (the whole tutorial, every command of it: 2 s)
def test_tutorial_runs(tmp_path, monkeypatch, capsys):
    from kinecal.cli import main

    monkeypatch.chdir(tmp_path)
    blocks = _blocks(PAGE.read_text(encoding="utf-8"))
    assert [k for k, _ in blocks].count("sh") >= 7
    ran = []
    for kind, body in blocks:
        if kind in ("csv", "text"):
            (tmp_path / "targets.csv").write_text(body)
            continue
        for line in body.strip().splitlines():
            args = shlex.split(line, comments=True)
            if not args:
                continue
            if args[0] == "cp":  # from the repository
                shutil.copy(ROOT / args[1], tmp_path / args[2])
                continue
            assert args[0] == "kinecal", line
            code = main(args[1:])
            out = capsys.readouterr()
            assert code == 0, (line, out.err)
            ran.append(args[1])
    assert ran == [
        "import-urdf",
        "plan",
        "simulate",
        "calibrate",
        "calibrate",
        "evaluate",
        "compensate",
        "export-urdf",
    ]

    # The quoted accuracy (0.033 mm held out, the truth 0.026 mm): within 1.3x of the
    # truth on the new session; the nominal robot far worse.
    def rms(model: str) -> float:
        main(
            [
                "evaluate",
                "session/test.csv",
                "--model",
                model,
                "--refit",
                "user",
                "--json",
            ]
        )
        return float(json.loads(capsys.readouterr().out)["rms_mm"])

    truth, cal, auto = (
        rms("session/truth.yaml"),
        rms("cal/model.yaml"),
        rms("cal-auto/model.yaml"),
    )
    assert cal < 1.3 * truth and auto < 1.3 * truth and cal < 0.04
    corrected = (tmp_path / "corrected.csv").read_text().splitlines()
    assert len(corrected) == 5 and all(r.endswith(",ok") for r in corrected[1:])
    assert (tmp_path / "arm7-calibrated.urdf").exists()


def test_tutorial_urdf_is_the_independent_arm():
    """docs/tutorial/arm7.urdf is the arm of tests/independent_arm.py, and its import
    reproduces that simulator's flange."""
    path = ROOT / "docs" / "tutorial" / "arm7.urdf"
    assert urdf_text().split("<robot", 1)[1] in path.read_text()
    robot = robot_from_urdf(path, tip="flange")
    q = random_poses(5, np.random.default_rng(0))
    p = true_arm(0, exact=True).measure(q, None, iterations=0)
    np.testing.assert_allclose(robot.fk_flange(q)[:, :3, 3], p, atol=1e-12)


def test_readme_says_how_to_get_kinecal_on_the_path():
    head = "\n".join((ROOT / "README.md").read_text().splitlines()[:25])
    assert "pip install -e ." in head and ".venv/bin" in head and "PATH" in head
    assert "docs/tutorial.md" in head
