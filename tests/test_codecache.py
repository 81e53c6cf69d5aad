"""Issue 36: the kinecal program keeps the compiled methods of dataclasses between runs
(kinecal._codecache); the methods are the ones dataclasses makes, a library user's
process keeps its dataclasses module, and a damaged or foreign file is not used."""

from __future__ import annotations

import builtins
import dataclasses
import marshal
import subprocess
import sys

import pytest

from kinecal import _codecache

SOURCE = """
import dataclasses

@dataclasses.dataclass(frozen=True)
class Pose:
    name: str
    x_mm: float = 0.0
    tags: list = dataclasses.field(default_factory=list)
"""


@pytest.fixture
def cache(monkeypatch, tmp_path):
    """The cache in a folder of the test's own, installed in this process for the
    test only (dataclasses' exec restored after it)."""
    path = tmp_path / "__pycache__" / "dataclass-methods.bin"
    monkeypatch.setattr(_codecache, "cache_file", lambda: path)
    monkeypatch.setattr(_codecache, "_codes", {})
    monkeypatch.setattr(_codecache, "_added", 0)
    monkeypatch.setattr(dataclasses, "exec", builtins.exec, raising=False)
    monkeypatch.setattr(sys, "dont_write_bytecode", False)
    return path


def _pose_class():
    ns: dict = {"__name__": "poses"}
    # (not with this module's __future__ annotations: real objects in annotations)
    builtins.exec(compile(SOURCE, "poses.py", "exec", dont_inherit=True), ns)
    return ns["Pose"]


def _same_code(a, b) -> bool:
    fields = ("co_code", "co_consts", "co_names", "co_varnames", "co_flags")
    return all(getattr(a, f) == getattr(b, f) for f in fields)


def test_the_methods_are_the_ones_dataclasses_makes(cache):
    plain = _pose_class()
    assert _codecache.install()
    cached = _pose_class()
    for name in ("__init__", "__setattr__", "__delattr__", "__eq__", "__repr__"):
        assert _same_code(getattr(plain, name).__code__, getattr(cached, name).__code__)
    # no __future__ flags of kinecal's module: annotations are objects, as before
    assert cached.__init__.__annotations__ == plain.__init__.__annotations__
    assert cached.__init__.__annotations__["x_mm"] is float
    p = cached("a", 2.0)
    assert (p, p.tags) == (cached("a", 2.0), [])
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.x_mm = 1.0


def _count_compiles(monkeypatch) -> list[str]:
    """The sources the code cache compiles from now on (its ``compile`` counted)."""
    compiled: list[str] = []

    def counted(source, *a, **k):
        compiled.append(source)
        return builtins.compile(source, *a, **k)

    monkeypatch.setattr(_codecache, "compile", counted, raising=False)
    return compiled


def test_a_text_is_compiled_once_and_kept_for_the_next_run(cache, monkeypatch):
    _codecache.install()
    _pose_class()
    _codecache.save()
    assert cache.is_file()
    monkeypatch.setattr(_codecache, "_codes", {})  # the next run
    compiled = _count_compiles(monkeypatch)
    _codecache.install()
    assert _pose_class()("b").x_mm == 0.0
    assert compiled == []


def test_no_file_under_dont_write_bytecode_and_a_bad_file_is_not_used(cache):
    _codecache.install()
    _pose_class()
    sys.dont_write_bytecode = True
    _codecache.save()
    assert not cache.exists()
    cache.parent.mkdir()
    for bad in (b"not marshal", marshal.dumps(((0, "other-python", 0), {"x": 1}))):
        cache.write_bytes(bad)
        _codecache._codes.clear()
        assert _codecache.install()
        assert _codecache._codes == {}
        assert _pose_class()("c").name == "c"


def test_only_the_program_installs_it():
    """``kinecal.cli.main`` (a library user's call) leaves dataclasses alone; the
    program (kinecal._entry.run) compiles through the cache."""
    code = (
        "import dataclasses, sys\nfrom kinecal.cli import main\n"
        "main(['robots'])\nprint('LIB', hasattr(dataclasses, 'exec'))\n"
        "from kinecal import _entry\n"
        "_entry.leave = lambda code: print('PROG', dataclasses.exec.__module__)\n"
        "sys.argv = ['kinecal', 'robots']\n_entry.run()\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 0, res.stderr
    assert "LIB False" in res.stdout and "PROG kinecal._codecache" in res.stdout


def test_beyond_the_limit_only_the_last_runs_texts_are_kept(cache, monkeypatch):
    monkeypatch.setattr(_codecache, "_used", set())
    monkeypatch.setattr(_codecache, "MAX_CODES", 3)
    _codecache.install()
    for i in range(5):
        _codecache.exec_cached(f"x = {i}", {})
    _codecache.save()  # (5 texts, all used: kept)
    _codecache._used.clear()
    _codecache._codes.clear()
    _codecache.install()
    _codecache.exec_cached("x = 1", {})
    _codecache.exec_cached("y = 2", {})
    _codecache.save()
    _, codes = marshal.loads(cache.read_bytes())
    assert sorted(codes) == ["x = 1", "y = 2"]


def test_a_damaged_entry_is_compiled_again(cache, monkeypatch):
    _codecache.install()
    _pose_class()
    _codecache.save()
    key, codes = marshal.loads(cache.read_bytes())
    cache.write_bytes(marshal.dumps((key, dict.fromkeys(codes, b"\x00damaged"))))
    monkeypatch.setattr(_codecache, "_codes", {})
    compiled = _count_compiles(monkeypatch)
    _codecache.install()
    assert _pose_class()("d").name == "d"
    assert len(compiled) == len(codes)
