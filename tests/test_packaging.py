"""Release files and documentation (issue 37): the API reference lists every public name,
the examples use public names only, ``kinecal --version`` names the model code, and the
numpy fallback warns once."""

from __future__ import annotations

import ast
import importlib
import re
import tomllib
import warnings
from pathlib import Path

import pytest
import yaml

import kinecal
from kinecal.cli import main
from kinecal.models import _kernel

ROOT = Path(__file__).resolve().parent.parent
API = ROOT / "docs" / "api"
PACKAGES = (
    "identification",
    "identification.selection",
    "measurement",
    "io",
    "planning",
    "compensation",
    "robot",
    "sensor",
    "models",
    "workflows",
    "iso9283",
)
_DIRECTIVE = re.compile(r"^\.\. auto(?:class|function|data):: (\w+)\s*$", re.M)


def _summary_names(text: str) -> list[str]:
    """The names of the page's autosummary table (indented lines after its options)."""
    block = text.split(".. autosummary::", 1)[1].split("\n\n", 2)[1]
    return [line.strip() for line in block.splitlines()]


@pytest.mark.parametrize("package", PACKAGES)
def test_api_reference_lists_every_public_name(package):
    page = API / f"{package}.rst"
    assert page.exists(), f"{page} missing: run python docs/api_pages.py"
    text = page.read_text(encoding="utf-8")
    public = set(importlib.import_module(f"kinecal.{package}").__all__)
    documented = _DIRECTIVE.findall(text)
    assert len(documented) == len(set(documented)), "a name is documented twice"
    missing, extra = public - set(documented), set(documented) - public
    assert not missing and not extra, (
        f"docs/api/{package}.rst is out of date (python docs/api_pages.py): "
        f"missing {sorted(missing)}, not public {sorted(extra)}"
    )
    assert set(_summary_names(text)) == public
    assert f"automodule:: kinecal.{package}" in text
    assert f"\n   {package}\n" in (API / "index.rst").read_text(encoding="utf-8")


def test_docs_pages_are_all_in_the_site():
    """Every Markdown page of docs/ is in the site's table of contents."""
    index = (ROOT / "docs" / "index.md").read_text(encoding="utf-8")
    entries = set(re.findall(r"^([\w/-]+)$", index, re.M))
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} - {"index"}
    assert pages <= entries, sorted(pages - entries)
    assert "api/index" in entries


def _private_imports(path: Path) -> list[str]:
    """``kinecal`` imports of a script that name a private module or name."""
    bad = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith(
            "kinecal"
        ):
            module = node.module or ""
            for a in node.names:
                if any(p.startswith("_") for p in [*module.split("."), a.name]):
                    bad.append(f"{module}.{a.name}")
        elif isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] == "kinecal" and any(p.startswith("_") for p in parts):
                    bad.append(a.name)
    return bad


def test_examples_use_public_names_only(tmp_path):
    scripts = sorted((ROOT / "examples").glob("*.py"))
    assert scripts
    found = {p.name: _private_imports(p) for p in scripts}
    assert not any(found.values()), found
    # The check sees a private import.
    probe = tmp_path / "probe.py"
    probe.write_text("from kinecal.identification._lm import x\nimport kinecal._cpu\n")
    assert len(_private_imports(probe)) == 2


def test_version_names_the_model_code(capsys, monkeypatch):
    monkeypatch.delenv("KINECAL_KERNEL", raising=False)
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"kinecal {kinecal.__version__}\n")
    code = "compiled kernel" if _kernel.compiled_kernel_available() else "numpy"
    assert f"model code: {code}: " in out
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")
    assert main(["--version"]) == 0
    assert "model code: numpy: KINECAL_KERNEL=numpy is set" in capsys.readouterr().out


def test_numpy_fallback_warns_once_per_installation(tmp_path, monkeypatch):
    monkeypatch.setattr(_kernel, "_ckernel", None)
    monkeypatch.setattr(_kernel, "_warned", False)
    monkeypatch.setattr(_kernel, "_build_note", lambda: "error: command 'gcc' failed")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("KINECAL_KERNEL", raising=False)
    code, why = _kernel.kernel_status()
    assert code == "numpy" and "command 'gcc' failed" in why and "C compiler" in why
    with pytest.warns(UserWarning, match="numpy model code.*command 'gcc' failed"):
        _kernel._warn_not_built()
    assert len(list((tmp_path / "kinecal").iterdir())) == 1  # the marker
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _kernel._warn_not_built()  # this process: already warned
        monkeypatch.setattr(_kernel, "_warned", False)
        _kernel._warn_not_built()  # a new process of the same installation: the marker
        monkeypatch.setattr(_kernel, "_warned", False)
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "other"))
        monkeypatch.setenv("KINECAL_KERNEL", "numpy")
        _kernel._warn_not_built()  # numpy chosen: no warning


def test_release_files():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    project = meta["project"]
    assert project["license"] == "Apache-2.0"
    assert {"LICENSE", "NOTICE"} <= set(project["license-files"])
    assert "Apache License" in (ROOT / "LICENSE").read_text(encoding="utf-8")[:200]
    assert (Path(kinecal.__file__).parent / "py.typed").exists()
    assert "Typing :: Typed" in project["classifiers"]
    extras = project["optional-dependencies"]
    assert not any("matplotlib" in r for r in extras["all"])
    cff = yaml.safe_load((ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["version"] == kinecal.__version__
    assert cff["preferred-citation"]["doi"] == "10.3390/s24082559"
    manifest = (ROOT / "MANIFEST.in").read_text(encoding="utf-8")
    for tree in ("tests", "docs", "examples"):
        assert f"graft {tree}" in manifest
    assert "Makefile" in manifest and "LICENSE" in manifest
