"""Result folders staged and moved into place (kinecal._outputs, issue 21)."""

from __future__ import annotations

import json

import pytest

from kinecal.io import output_transaction, prepare_output_dir


def _names(d):
    return sorted(p.name for p in d.iterdir())


def test_new_folder_appears_whole_at_the_end(tmp_path):
    out = tmp_path / "res"
    with output_transaction():
        d = prepare_output_dir(out, ["a.csv", "b.csv"])
        assert d != out and d.parent == tmp_path and not out.exists()
        (d / "a.csv").write_text("a\n")
        (d / "b.csv").write_text("b\n")
        assert not out.exists()  # nothing visible until the block ends
    assert _names(out) == ["a.csv", "b.csv"]
    assert _names(tmp_path) == ["res"]  # no staging left


def test_failure_leaves_nothing(tmp_path):
    out = tmp_path / "res"
    with pytest.raises(RuntimeError), output_transaction():
        d = prepare_output_dir(out, ["a.csv"])
        (d / "a.csv").write_text("a\n")
        raise RuntimeError("crash")
    assert _names(tmp_path) == []


def test_existing_folder_keeps_other_files_and_without_force_adds(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    (out / "mine.txt").write_text("x\n")
    with output_transaction():
        d = prepare_output_dir(out, ["a.csv"])
        assert d.parent == out  # staged inside the existing folder
        (d / "a.csv").write_text("a\n")
    assert _names(out) == ["a.csv", "mine.txt"]


def test_force_replaces_the_whole_earlier_result(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    for name in ("a.csv", "old-extra.csv", "manifest.json", "mine.txt"):
        (out / name).write_text("old\n")
    (out / "manifest.json").write_text(
        json.dumps({"files": ["a.csv", "old-extra.csv"]})
    )
    (out / "sub").mkdir()
    (out / "sub" / "x").write_text("old\n")
    with output_transaction():
        d = prepare_output_dir(out, ["a.csv", "sub", "manifest.json"], force=True)
        (d / "a.csv").write_text("new\n")
        (d / "sub").mkdir()
        (d / "sub" / "y").write_text("new\n")
        (d / "manifest.json").write_text(json.dumps({"files": ["a.csv", "sub"]}))
    # old-extra.csv (listed by the old manifest) goes; the user's file stays
    assert _names(out) == ["a.csv", "manifest.json", "mine.txt", "sub"]
    assert (out / "a.csv").read_text() == "new\n" and _names(out / "sub") == ["y"]


def test_clash_without_force_is_refused_before_the_work(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    (out / "a.csv").write_text("old\n")
    with pytest.raises(FileExistsError, match="use --force"), output_transaction():
        prepare_output_dir(out, ["model-*.yaml", "a.csv"])
    assert _names(out) == ["a.csv"]


def test_a_file_that_appears_meanwhile_is_not_overwritten(tmp_path):
    out = tmp_path / "res"
    out.mkdir()
    with pytest.raises(FileExistsError, match="appeared while"), output_transaction():
        d = prepare_output_dir(out, ["a.csv"])
        (d / "a.csv").write_text("new\n")
        (out / "a.csv").write_text("theirs\n")
    assert (out / "a.csv").read_text() == "theirs\n" and _names(out) == ["a.csv"]


def test_outside_a_transaction_the_folder_itself(tmp_path):
    out = tmp_path / "res"
    assert prepare_output_dir(out, ["a.csv"]) == out and out.is_dir()
