"""Write the API reference pages (docs/api/*.rst) from the packages' ``__all__``.

Run after a change to a public package's names: ``python docs/api_pages.py``. The pages
are committed, and tests/test_packaging.py checks that each lists exactly the package's
``__all__``, so a new public name without its page entry fails the tests.
"""

from __future__ import annotations

import importlib
import inspect
import sys
from pathlib import Path

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
HERE = Path(__file__).resolve().parent / "api"


def page(package: str) -> str:
    """The reST of one package's page: its docstring, a summary table, every name."""
    name = f"kinecal.{package}"
    module = importlib.import_module(name)
    names = sorted(module.__all__, key=lambda n: (n.lower(), n))
    lines = [
        name,
        "=" * len(name),
        "",
        f".. automodule:: {name}",
        "   :no-members:",
        "",
        f".. currentmodule:: {name}",
        "",
        ".. autosummary::",
        "   :nosignatures:",
        "",
        *(f"   {n}" for n in names),
        "",
    ]
    for n in names:
        obj = getattr(module, n)
        # A name re-exported from another documented package is indexed there only.
        again = ["   :no-index:"] if _home(package, n, obj) != package else []
        if inspect.isclass(obj):
            lines += [f".. autoclass:: {n}", "   :members:", *again, ""]
        elif callable(obj):
            lines += [f".. autofunction:: {n}", *again, ""]
        else:
            lines += [f".. autodata:: {n}", "   :no-value:", *again, ""]
    return "\n".join(lines)


def _home(package: str, name: str, obj: object) -> str:
    """The documented package whose private module defines ``name`` (the package
    itself where no other one does)."""
    source = inspect.getsource(importlib.import_module(f"kinecal.{package}"))
    for other in PACKAGES:
        if other == package:
            continue
        there = importlib.import_module(f"kinecal.{other}")
        if name in there.__all__ and getattr(there, name) is obj:
            if f"kinecal.{other}._" in source:
                return other
    return package


def main() -> int:
    HERE.mkdir(exist_ok=True)
    for package in PACKAGES:
        (HERE / f"{package}.rst").write_text(page(package), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
