"""Issue 36: the fixed costs of a whole ``kinecal calibrate`` process. The modules its
path no longer needs stay unimported (each cost is said where it was dropped), its
dataclasses compile no ``__eq__``/``__hash__``/``__repr__`` of their own (kinecal._record),
the data file is parsed once, and the program collects no garbage in a short command."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import threading

import numpy as np
import pytest

from kinecal._record import MutableRecord, Record, ReprRecord
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
    "logging",  # kinecal._log: debug/info messages reach logging once it is loaded
    "string",
    "queue",  # the kernel's thread pool (none on one thread)
    "hashlib",  # small files' SHA-256 by CPython's own (OpenSSL's load: 2.5-3 ms)
    "_hashlib",
}
# ... nor these, for the full model replacing an earlier result (--force)
NOT_IMPORTED_FULL = {
    "kinecal.models._numpy_forward",  # the compiled kernel evaluates the model
    "kinecal.models._numpy_jacobian",
    # leave-one-out errors: only where a rejection is tested or orientations weighed
    "kinecal.identification._press",
}
# Dataclasses calibrate loads that still compile an __eq__ or __repr__ of their own (the
# others are records of kinecal._record): one in a module outside issue 36's change.
OWN_METHODS = {"kinecal.models._kernel.KernelTables"}


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


def test_issue_36_full_calibrate_replacing_a_result_loads_no_more(data, tmp_path):
    """The full model over an earlier result (--force): no shutil (the staging folder
    and the replaced files removed with os), no numpy model code, no logging; and no
    dataclass on the way compiles its own __eq__/__repr__ beyond OWN_METHODS."""
    from kinecal.models import compiled_kernel_available

    out = tmp_path / "out"
    argv = ["calibrate", str(data), "--robot", "fanuc-lrmate200id", "--model", "full"]
    argv += ["--cv", "off", "--out", str(out), "--force", "-q"]
    code = (
        "import sys, json, dataclasses\nfrom kinecal.cli import main\n"
        f"code = main({argv!r})\n"
        "mods = [m for n, m in list(sys.modules.items()) if n.startswith('kinecal')]\n"
        "own = sorted(f'{c.__module__}.{c.__qualname__}' for m in mods\n"
        "    for c in vars(m).values() if isinstance(c, type)\n"
        "    and c.__module__ == m.__name__ and dataclasses.is_dataclass(c)\n"
        "    and ('__eq__' in vars(c) or '__repr__' in vars(c)))\n"
        "print(json.dumps([code, sorted(sys.modules), own]))"
    )
    for _ in range(2):  # a new folder, then the same one replaced
        res = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
        )
        assert res.returncode == 0, res.stderr
    rc, loaded, own = json.loads(res.stdout.splitlines()[-1])
    assert rc == 0 and (out / "report.html").is_file()
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["model.yaml", "report.json", "residuals.csv", "manifest.json", "report.html"]
    )  # the staging folder and the replaced files are gone
    spared = {"shutil", "bz2", "lzma", "logging", "queue"}
    if compiled_kernel_available():
        spared |= NOT_IMPORTED_FULL
    assert not spared & set(loaded), sorted(spared & set(loaded))
    assert set(own) <= OWN_METHODS, sorted(set(own) - OWN_METHODS)


def _twins(cls):
    """The plain dataclass of the same fields and flags as ``cls`` (a ReprRecord)."""
    frozen = cls.__dataclass_params__.frozen
    spec = [
        (f.name, f.type, dataclasses.field(repr=f.repr, compare=f.compare, hash=f.hash))
        for f in dataclasses.fields(cls)
    ]
    eq = issubclass(cls, Record)
    twin = dataclasses.make_dataclass(cls.__name__, spec, frozen=frozen, eq=eq)
    twin.__qualname__ = cls.__qualname__
    return twin


def _filled(cls, values):
    obj = object.__new__(cls)
    for f, v in zip(dataclasses.fields(cls), values, strict=True):
        object.__setattr__(obj, f.name, v)
    return obj


def _outcome(fn, *args):
    """What ``fn(*args)`` returns, or the type of what it raises."""
    try:
        return fn(*args)
    except Exception as exc:  # an exception is an outcome too
        return type(exc)


def _same_behaviour(cls, values, other_values):
    twin = _twins(cls)
    a, b, c = (_filled(cls, v) for v in (values, values, other_values))
    ta, tb, tc = (_filled(twin, v) for v in (values, values, other_values))
    assert repr(a) == repr(ta)
    for op in (
        lambda p, q, r: p == q,
        lambda p, q, r: p == r,
        lambda p, q, r: p != r,
        lambda p, q, r: p == 1,
        lambda p, q, r: p == p,
        # the hash; of objects compared as objects (their ids): whether they have one
        (lambda p, q, r: hash(p))
        if issubclass(cls, Record)
        else (lambda p, q, r: 0 * hash(p)),
    ):
        assert _outcome(op, a, b, c) == _outcome(op, ta, tb, tc)


def _kinecal_records():
    import importlib

    for name in ("cli._calibrate", "report._calibration", "workflows._calibrate"):
        importlib.import_module(f"kinecal.{name}")  # the calibrate path's modules
    seen, todo = set(), [ReprRecord]
    while todo:
        for sub in todo.pop().__subclasses__():
            if sub not in seen:
                seen.add(sub)
                todo.append(sub)
    return sorted(seen - {Record, MutableRecord}, key=str)


def test_issue_36_records_are_the_dataclasses_they_replace():
    """Every record is declared eq=False, repr=False (else dataclass writes its own); a
    Record frozen exactly when it is not a MutableRecord (a mutable class is
    unhashable); each has the repr, ==, != and hash (or none) of the plain dataclass
    (with eq=False for a ReprRecord alone) on the same field values."""
    records = _kinecal_records()
    assert len(records) >= 60
    for cls in records:
        p = cls.__dataclass_params__
        assert not (p.eq or p.repr or p.unsafe_hash or p.order), cls
        if issubclass(cls, Record):
            assert p.frozen != issubclass(cls, MutableRecord), cls
        assert not {"__eq__", "__hash__", "__repr__"} & set(vars(cls)), cls
        n = len(dataclasses.fields(cls))
        _same_behaviour(cls, [f"v{i}" for i in range(n)], [f"w{i}" for i in range(n)])
        _same_behaviour(cls, [(i, None) for i in range(n)], [i for i in range(n)])


def test_issue_36_record_methods_on_edge_cases():
    @dataclasses.dataclass(frozen=True, eq=False, repr=False)
    class A(Record):
        x: object
        y: object = dataclasses.field(default=0, repr=False)
        z: object = dataclasses.field(default=0, compare=False)
        h: object = dataclasses.field(default=0, hash=False)

    @dataclasses.dataclass(frozen=True, eq=False, repr=False)
    class B(A):
        w: object = 1

    @dataclasses.dataclass(eq=False, repr=False)
    class M(MutableRecord):
        x: object

    for cls, n in ((A, 4), (B, 5), (M, 1)):
        arr = np.arange(3.0)
        _same_behaviour(cls, [arr] * n, [arr.copy()] * n if n == 1 else [arr] * n)
        _same_behaviour(cls, list(range(n)), [*range(n - 1), 99])
        _same_behaviour(cls, [()] * n, [(1,)] * n)
    m = M(None)
    m.x = m  # a record inside its own repr
    assert repr(m) == "test_issue_36_record_methods_on_edge_cases.<locals>.M(x=...)"
    assert A(1) != B(1) and A(1, z=5) == A(1, z=6) and hash(A(1, h=2)) == hash(A(1))
    seen = []
    t = threading.Thread(target=lambda: seen.append(repr(A([1]))))
    t.start()
    t.join()
    assert seen == [repr(A([1]))]


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


def test_issue_36_kinecal_messages_reach_logging_once_it_is_loaded(caplog):
    import logging

    from kinecal._log import Logger

    caplog.set_level(logging.DEBUG, logger="kinecal.issue36")

    def emit():
        Logger("kinecal.issue36").debug("%s it %d", "stage", 3)
        Logger("kinecal.issue36").info("done")

    emit()
    debug, info = caplog.records[-2:]
    assert (debug.getMessage(), debug.levelno, debug.name) == (
        "stage it 3",
        logging.DEBUG,
        "kinecal.issue36",
    )
    assert (info.getMessage(), info.levelno) == ("done", logging.INFO)
    assert debug.funcName == info.funcName == "emit"  # the caller, not kinecal._log
    assert debug.pathname == __file__


def test_issue_36_result_trash_removed_as_shutil_would(tmp_path):
    from kinecal._outputs import _rmtree

    trash = tmp_path / "staging"
    (trash / ".replaced" / "deeper").mkdir(parents=True)
    for f in ("a.txt", ".replaced/manifest.json", ".replaced/deeper/b"):
        (trash / f).write_text("x")
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "keep.txt").write_text("x")
    (trash / "link").symlink_to(outside)  # a link inside: removed, not followed
    _rmtree(trash)
    assert not trash.exists() and (outside / "keep.txt").is_file()
    linked = tmp_path / "linked"
    linked.symlink_to(outside)  # the folder itself a link: left alone (as rmtree)
    _rmtree(linked)
    assert linked.is_symlink() and (outside / "keep.txt").is_file()
    _rmtree(tmp_path / "missing")  # nothing there: quietly nothing


def test_issue_36_the_full_model_lacks_no_terms_without_a_second_build(monkeypatch):
    from kinecal.identification import _structure
    from kinecal.models import CalibrationModel
    from kinecal.robot import load_robot

    robot = load_robot("fanuc-lrmate200id")
    kinematic = CalibrationModel(robot, _structure.ModelSpec.preset("kinematic"))
    full = CalibrationModel(robot, _structure._full_spec(kinematic))
    assert _structure._lacks_terms(kinematic)  # built: the full model has more

    def build(*args):
        raise AssertionError("built again")

    monkeypatch.setattr(_structure, "CalibrationModel", build)
    assert not _structure._lacks_terms(full)
