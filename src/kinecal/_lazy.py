"""Packages whose public names load their private module on first use (PEP 562).

A package's ``__init__`` that imports every module at once makes each command pay for
all of them: ``kinecal sensor fit-sphere`` imported SciPy's image filters through the
stripe extractor (0.5-0.8 s) for a 50 ms fit, and reading a CSV imported the whole
identification. With :func:`exports` the package lists where each public name lives and
imports it when it is first asked for (``from kinecal.sensor import fit_sphere``); the
names, ``__all__`` and ``dir()`` stay as they were. Each package also imports the names
under ``typing.TYPE_CHECKING``, so type checkers see them as before.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable
from typing import Any

__all__ = ["exports"]


def exports(
    package: str, where: dict[str, tuple[str, ...]]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` of ``package`` whose public names are
    ``where[module]`` in its private submodules ``module`` (or in the module of that
    full name when it starts with ``kinecal.``).

    The package defines ``__all__`` first; it must hold exactly these names. A name, once
    imported, is set on the package, so later lookups are plain attribute reads.

    Raises
    ------
    ImportError
        ``__all__`` and ``where`` name different things (a package out of step).
    """
    home = {name: module for module, names in where.items() for name in names}
    listed = set(getattr(sys.modules[package], "__all__", ()))
    if listed != set(home):
        raise ImportError(
            f"{package}: __all__ and the lazy exports differ in "
            f"{sorted(listed ^ set(home))}"
        )

    def __getattr__(name: str) -> Any:
        module = home.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        full = module if module.startswith("kinecal.") else f"{package}.{module}"
        value = getattr(importlib.import_module(full), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted({*vars(sys.modules[package]), *home})

    return __getattr__, __dir__
