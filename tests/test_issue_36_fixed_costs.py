"""Issue 36: the fixed costs of a whole ``kinecal calibrate`` process. The modules its
path no longer needs stay unimported (each cost is said where it was dropped), the data
file is parsed once, and the program collects no garbage in a short command."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from kinecal.io import measurements_to_csv
from kinecal.simulation import LaserTracker, experiment2

# modules calibrate (with its report) imported for nothing before issue 36
NOT_IMPORTED = {
    "tempfile",  # atomic writes (with random, bz2, lzma through shutil)
    "random",
    "shutil",  # a new result folder leaves nothing to remove
    "html",  # report escaping (html.entities)
    "html.entities",
    "csv",  # only for quoted CSV files
    "gzip",  # numpy's datasource: residuals.csv parsed again for the report
    "bz2",
    "lzma",
    "yaml",  # model.yaml written without PyYAML, and not read back for the report
    "kinecal.io._compensation_csv",  # compensate's TARGETS (a dataclass of 11 fields)
    "numpy.random",  # the compliance bound's poses are a fixed sequence (13 ms)
}


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("fixed")
    exp = experiment2(3, tracker=LaserTracker(5e-6, 0.0), n_side=4)
    p = d / "train.csv"
    p.write_text(measurements_to_csv(exp.train, exp.truth.robot))
    return p


def test_issue_36_calibrate_imports_only_what_it_uses(data, tmp_path):
    argv = ["calibrate", str(data), "--robot", "fanuc-lrmate200id", "--model"]
    argv += ["kinematic", "--cv", "off", "--out", str(tmp_path / "out"), "-q"]
    code = (
        "import sys, json\nfrom kinecal.cli import main\n"
        f"code = main({argv!r})\n"
        "print(json.dumps([code, sorted(sys.modules)]))"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr
    rc, loaded = json.loads(res.stdout.splitlines()[-1])
    assert rc == 0 and (tmp_path / "out" / "report.html").is_file()
    assert "kinecal.report._calibration" in loaded  # the report was drawn
    from kinecal.io._yaml_plain import dump

    # PyYAML writes model.yaml where the data file's name needs quotes (info.source)
    spared = NOT_IMPORTED - ({"yaml"} if dump({"source": str(data)}) is None else set())
    assert not spared & set(loaded), sorted(spared & set(loaded))


def test_issue_36_temperature_range_parses_no_file_without_the_column(
    data, monkeypatch
):
    from kinecal import io
    from kinecal.report._certificate import temperature_range

    def parse(path):
        raise AssertionError("parsed again")

    monkeypatch.setattr(io, "read_table", parse)
    assert temperature_range(str(data), [2, 3]) is None
    with_t = data.with_name("with_t.csv")
    lines = data.read_text().splitlines()
    with_t.write_text(
        "\n".join([lines[0] + ",temperature_c"] + [s + ",20.5" for s in lines[1:]])
    )
    with pytest.raises(AssertionError, match="parsed again"):
        temperature_range(str(with_t), [2, 3])


def test_issue_36_the_program_collects_no_garbage_in_a_short_command(data, tmp_path):
    """kinecal (the program) lets 100 000 new objects come before a collection: a small
    calibrate runs none (the default threshold ran ~60, over the imports' objects)."""
    argv = ["kinecal", "calibrate", str(data), "--robot", "fanuc-lrmate200id"]
    argv += ["--model", "kinematic", "--cv", "off", "--out", str(tmp_path / "o"), "-q"]
    code = (
        "import gc, sys\nfrom kinecal import _entry\nruns = []\n"
        "gc.callbacks.append(lambda phase, info: runs.append(phase))\n"
        "def leave(code):\n"
        "    print('RESULT', code, gc.get_threshold()[0], runs.count('stop'))\n"
        "    raise SystemExit(0)\n"
        f"_entry.leave = leave\nsys.argv = {argv!r}\n_entry.run()"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr
    rc, young, collections = res.stdout.split("RESULT")[-1].split()
    assert (int(rc), int(young), int(collections)) == (0, 100_000, 0)


def test_issue_36_main_keeps_the_callers_garbage_collection(capsys):
    import gc

    from kinecal.cli import main

    before = gc.get_threshold()
    assert main(["robots"]) == 0
    assert gc.get_threshold() == before
