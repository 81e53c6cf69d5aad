"""Second fault audit: set and marker labels of compensate's TARGETS against the
model's, refused as ``kinecal evaluate`` refuses them. In-process."""

from __future__ import annotations

import pytest

from tests.cli_contract import failed_with, make_point_data, run_kinecal


def _with_column(src, dst, name, labels):
    lines = src.read_text().splitlines()
    out = [lines[0] + f",{name}"]
    out += [f"{ln},{labels(k)}" for k, ln in enumerate(lines[1:])]
    dst.write_text("\n".join(out) + "\n")
    return dst


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = make_point_data(tmp_path_factory.mktemp("labels"))
    from kinecal.cli import main

    train = _with_column(
        d["train"], d["dir"] / "train_m1.csv", "marker", lambda k: "m1"
    )
    argv = ["calibrate", str(train), "--robot", "fanuc-lrmate200id", "--model"]
    code = main([*argv, "kinematic", "--out", str(d["dir"] / "m1"), "-q"])
    assert code == 0
    d["model_m1"] = d["dir"] / "m1" / "model.yaml"
    return d


def test_targets_of_another_marker_are_refused(capsys, tmp_path, data):
    """Targets of marker 'm2' against a model of marker 'm1' only: compensated for
    m1's point with exit 0 (evaluate refuses such data)."""
    tg = _with_column(data["targets"], tmp_path / "t.csv", "marker", lambda k: "m2")
    out = tmp_path / "c.csv"
    res = run_kinecal(
        capsys, "compensate", tg, "--model", data["model_m1"], "--out", out
    )
    failed_with(res, "t.csv", "'marker'", "'m2'", "'m1'")
    assert not out.exists()
    tg = _with_column(data["targets"], tmp_path / "t1.csv", "marker", lambda k: "m1")
    res = run_kinecal(
        capsys, "compensate", tg, "--model", data["model_m1"], "--out", out,
        "--allow-unreachable",
    )  # fmt: skip
    assert res.code == 0, str(res)


def test_targets_of_two_sets_against_a_model_of_one_are_refused(capsys, tmp_path, data):
    """Two user frames' targets mapped onto the model's one frame, with exit 0."""
    tg = _with_column(data["targets"], tmp_path / "t.csv", "set", lambda k: "AB"[k % 2])
    out = tmp_path / "c.csv"
    res = run_kinecal(capsys, "compensate", tg, "--model", data["model"], "--out", out)
    failed_with(res, "t.csv", "'set'", "'A', 'B'", "one set")
    assert not out.exists()
