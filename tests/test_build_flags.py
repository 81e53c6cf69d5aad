"""setup.py: no fused multiply-adds under any compiler (issue 34, small items); -O3."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _build_ext_class():
    with mock.patch("setuptools.setup"), mock.patch.object(sys, "argv", ["setup.py"]):
        ns = runpy.run_path(str(ROOT / "setup.py"))
    return ns["BuildExt"]


@pytest.mark.parametrize(
    ("kind", "want"), [("unix", "-ffp-contract=off"), ("msvc", "/FI")]
)
def test_every_compiler_turns_contractions_off(tmp_path, kind, want):
    BuildExt = _build_ext_class()
    ext = SimpleNamespace(extra_compile_args=[])
    cmd = BuildExt.__new__(BuildExt)
    cmd.compiler = SimpleNamespace(compiler_type=kind)
    cmd.extensions = [ext]
    cmd.build_temp = str(tmp_path)
    with mock.patch("setuptools.command.build_ext.build_ext.build_extensions"):
        cmd.build_extensions()
    assert any(a.startswith(want) for a in ext.extra_compile_args)
    if kind == "msvc":
        assert "/fp:precise" in ext.extra_compile_args
        header = Path(ext.extra_compile_args[-1][3:])
        assert header.read_text().strip() == "#pragma fp_contract(off)"


def test_gcc_and_clang_optimise_with_o3_whatever_the_python(tmp_path):
    """-O3 after the Python's own flags (Debian's pass -O2: the kernel 1.3x slower)."""
    BuildExt = _build_ext_class()
    ext = SimpleNamespace(extra_compile_args=[])
    cmd = BuildExt.__new__(BuildExt)
    cmd.compiler = SimpleNamespace(compiler_type="unix")
    cmd.extensions = [ext]
    cmd.build_temp = str(tmp_path)
    with mock.patch("setuptools.command.build_ext.build_ext.build_extensions"):
        cmd.build_extensions()
    assert "-O3" in ext.extra_compile_args
