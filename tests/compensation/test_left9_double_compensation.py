"""Double compensation: ``compensate`` marks the programs it writes with one comment
line and refuses them (and its own CORRECTED.csv) as input.

Before, a corrected program fed back into ``compensate`` had its joint targets corrected
a second time (exit 0; the sample URScript's joints moved by 0.85 deg again on the
tracker twin, as much as by the first correction),
and a CORRECTED.csv came back with its ``_program`` columns written twice, the second
copy holding the corrected joints."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.io import read_program
from kinecal.io._programs import program_joints
from kinecal.workflows._provenance import (
    MARK,
    mark_compensated,
    refuse_compensated_program,
)
from tests.compensation.conftest import box_poses, write_targets_csv
from tests.helpers import unmarked

PROGRAMS = Path(__file__).parents[1] / "data" / "programs"
# FANUC's P[2] is a Cartesian target in UT 1.
FRAMES = {".ls": ["--utool", "1=0,0,100,0,0,0"]}
FORMATS = {".ls": "fanuc-ls", ".script": "urscript", ".mod": "rapid", ".dat": "krl"}


def _compensate(run_cli, model_file, src: Path, out: Path, *extra: str):
    return run_cli(
        "compensate", str(src), "--model", str(model_file), "--out", str(out),
        "--allow-unreachable", *FRAMES.get(src.suffix, []), *extra,
    )  # fmt: skip


@pytest.mark.parametrize("ext", sorted(FORMATS))
def test_a_corrected_program_is_marked_and_refused(
    tracker_twin, model_file, run_cli, tmp_path, ext
):
    src = tmp_path / f"prog{ext}"
    shutil.copy(PROGRAMS / f"pick_demo{ext}", src)
    out = tmp_path / f"corrected{ext}"
    res = _compensate(run_cli, model_file, src, out)
    assert res.returncode == 0, res.stderr
    text, old = out.read_bytes().decode(), src.read_bytes().decode()
    # one comment line more, with the file's line ends; the rest as before
    marked = [ln for ln in text.splitlines() if MARK in ln]
    assert len(marked) == 1
    assert len(unmarked(text, old).splitlines()) == len(old.splitlines())
    assert ("\r\n" in text) == ("\r\n" in old)
    # kinecal's readers read the same targets in it
    robot = tracker_twin.calibrated.model.robot
    q_old = program_joints(read_program(src), robot)
    q_new = program_joints(read_program(out), robot)
    assert q_new.shape == q_old.shape
    # fed back: refused (exit 2), naming the file and the line; nothing written
    again = tmp_path / f"again{ext}"
    res = _compensate(run_cli, model_file, out, again)
    assert res.returncode == 2, res.stderr
    line = text[: text.index(MARK)].count("\n") + 1
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("Error: ") and f"corrected{ext}: line {line}:" in last
    assert "twice" in last and "delete that comment line" in last
    assert not again.exists()


def test_the_override_is_deleting_the_mark(tracker_twin, model_file, run_cli, tmp_path):
    """Without its comment line the corrected program is compensated again, and its
    joints move a second time: what the refusal prevents."""
    src = tmp_path / "prog.script"
    shutil.copy(PROGRAMS / "pick_demo.script", src)
    out, twice = tmp_path / "c.script", tmp_path / "twice.script"
    assert _compensate(run_cli, model_file, src, out).returncode == 0
    lines = out.read_text().splitlines(keepends=True)
    out.write_text("".join(ln for ln in lines if MARK not in ln))
    res = _compensate(run_cli, model_file, out, twice)
    assert res.returncode == 0, res.stderr
    robot = tracker_twin.calibrated.model.robot
    q1 = program_joints(read_program(out), robot)
    q2 = program_joints(read_program(twice), robot)
    q0 = program_joints(read_program(src), robot)
    first = np.degrees(np.abs(q1 - q0)).max()
    assert first > 0.1
    assert np.degrees(np.abs(q2 - q1)).max() > 0.5 * first  # corrected twice


def test_corrected_csv_is_refused_as_targets(
    tracker_twin, model_file, run_cli, tmp_path
):
    q = box_poses(np.random.default_rng(2), 5)
    p = tracker_twin.truth.evaluate(q)[0]
    targets = write_targets_csv(tmp_path / "targets.csv", p, q)
    out = tmp_path / "corrected.csv"
    assert run_cli("compensate", str(targets), "--model", str(model_file),
                   "--out", str(out), "--allow-unreachable").returncode == 0  # fmt: skip
    res = run_cli("compensate", str(out), "--model", str(model_file),
                  "--out", str(tmp_path / "again.csv"))  # fmt: skip
    assert res.returncode == 2
    last = res.stderr.strip().splitlines()[-1]
    assert "corrected.csv: columns j1_deg_program, j2_deg_program.." in last
    assert "remove its _program columns" in last
    assert not (tmp_path / "again.csv").exists()
    # the override: without the _program columns it is a TARGETS file again
    rows = [r.split(",") for r in out.read_text().splitlines()]
    keep = [k for k, c in enumerate(rows[0]) if not c.endswith("_program")]
    (tmp_path / "t2.csv").write_text(
        "\n".join(",".join(r[k] for k in keep) for r in rows) + "\n"
    )
    res = run_cli("compensate", str(tmp_path / "t2.csv"), "--model", str(model_file),
                  "--out", str(tmp_path / "again.csv"), "--allow-unreachable")  # fmt: skip
    assert res.returncode == 0, res.stderr


def test_mark_placement_per_format():
    fanuc = (
        "/PROG  A\r\n/ATTR\r\nLINE_COUNT\t= 2;\r\n/MN\r\n   1:  J P[1] 100% FINE ;\r\n"
        "   2:  ! note ;\r\n/POS\r\n/END\r\n"
    )
    out = mark_compensated(fanuc, "fanuc-ls")
    assert f"   3:  !{MARK} ;\r\n/POS" in out and "LINE_COUNT\t= 3;" in out
    assert len(f"!{MARK}") <= 32  # a FANUC remark
    krl = "DEF a( )\nPTP {A1 1}\nEND\n\nDEF b( )\nEND\n"
    assert mark_compensated(krl, "krl").endswith(f"; {MARK}; compensate the "
                                                 "original, not this\nEND\n")  # fmt: skip
    rapid = "MODULE M\n  PROC main()\n  ENDPROC\nENDMODULE"
    assert re.search(
        rf"ENDPROC\n! {MARK}.*\nENDMODULE$", mark_compensated(rapid, "rapid")
    )
    assert mark_compensated("def p():\nend", "urscript").endswith(f"end\n# {MARK}"
        "; compensate the original, not this\n")  # fmt: skip


def test_the_mark_counts_only_in_a_comment(tmp_path):
    text = f'def p():\n  popup("{MARK}")\n  movej([0, 0, 0, 0, 0, 0])\nend\n'
    refuse_compensated_program("p.script", text, "urscript")  # a string: not the mark
    with pytest.raises(DataError, match=r"p.script: line 5: 'kinecal compensated'"):
        refuse_compensated_program("p.script", mark_compensated(text, "urscript"),
                                   "urscript")  # fmt: skip
