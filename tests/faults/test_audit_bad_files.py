"""Issue 35 (7), the audit: every command that reads a file, given every kind of bad
file in that place (missing, empty, a folder, binary bytes, a file of another kind):
exit 2 and one ``Error:`` line that names the file; nothing written."""

from __future__ import annotations

import pytest

from tests.cli_contract import failed_with, run_kinecal

ROBOT = "fanuc-lrmate200id"

# Each command with one slot {bad} for the file under test; other names from `data`.
COMMANDS = {
    "calibrate DATA": ["calibrate", "{bad}", "--robot", ROBOT, "--out", "{out}"],
    "calibrate --robot": ["calibrate", "{train}", "--robot", "{bad}", "--out", "{out}"],
    "evaluate DATA": ["evaluate", "{bad}", "--model", "{model}"],
    "evaluate --model": ["evaluate", "{test}", "--model", "{bad}"],
    "compensate TARGETS": ["compensate", "{bad}", "--model", "{model}", "--out", "{out}"],
    "compensate --model": ["compensate", "{targets}", "--model", "{bad}", "--out", "{out}"],
    "fk --model": ["fk", "--model", "{bad}", "0", "0", "0", "0", "90", "0"],
    "fk --robot": ["fk", "--robot", "{bad}", "0", "0", "0", "0", "90", "0"],
    "export-urdf MODEL": ["export-urdf", "{bad}", "--out", "{out}"],
    "plan --candidates": [
        "plan", "--robot", ROBOT, "--candidates", "{bad}", "--poses", "5", "--out", "{out}",
    ],
    "plan --model": ["plan", "--model", "{bad}", "--add", "3", "--out", "{out}"],
    "compare TRAIN": [
        "compare", "{bad}", "{test}", "--robot", ROBOT, "--models", "kinematic",
        "--out", "{out}",
    ],
    "sensor fit-sphere": ["sensor", "fit-sphere", "{bad}"],
    "sensor reconstruct --sensor": [
        "sensor", "reconstruct", "{dir}", "--sensor", "{bad}", "--out", "{out}",
    ],
    "calibrate --targets": [
        "calibrate", "{train}", "--robot", ROBOT, "--targets", "{bad}", "--out", "{out}",
    ],
    "report FOLDER": ["report", "{bad}", "--out", "{out}"],
    "sensor stripes": ["sensor", "stripes", "{bad}", "--out", "{out}"],
}  # fmt: skip


def _bad_files(data, d):
    """Bad files by kind; each a path (the file under test is named in the message)."""
    (d / "empty.csv").write_text("")
    (d / "binary.yaml").write_bytes(bytes(range(256)) * 4)
    (d / "folder").mkdir()
    return {
        "missing": d / "missing.yaml",
        "empty": d / "empty.csv",
        "binary": d / "binary.yaml",
        "folder": d / "folder",
        # a file of another kind in this place: the model where data or a robot is
        # expected, data where a model is expected
        "other-kind": None,
    }


def _other_kind(data, slot_name):
    wants_model = "--model" in slot_name or slot_name == "export-urdf MODEL"
    return data["test"] if wants_model else data["model"]


KINDS = ["missing", "empty", "binary", "folder", "other-kind"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_issue_35_every_command_every_bad_file(data, capsys, tmp_path, command, kind):
    bad = _bad_files(data, tmp_path)[kind] or _other_kind(data, command)
    names = {**{k: str(v) for k, v in data.items()}, "bad": str(bad)}
    names["out"] = str(tmp_path / "out")
    args = [a.format(**names) for a in COMMANDS[command]]
    res = run_kinecal(capsys, *args)
    failed_with(res, bad.name)
    assert not (tmp_path / "out").exists()
