"""Shared fixtures: a seeded random generator (never global np.random), the CLI run in a
subprocess, as a user would, and the model's Jacobian storage poisoned with NaN."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator

import numpy as np
import pytest


@pytest.fixture(autouse=True)
def _poisoned_jacobian_storage(monkeypatch: pytest.MonkeyPatch) -> None:
    """The model's Jacobian starts uninitialised (np.empty); here it starts as NaN, so an
    entry that evaluate() forgets to write fails every test that reads it (FD checks,
    fits) instead of passing on memory that happened to be zero."""
    from kinecal.models import _model

    monkeypatch.setattr(_model, "_alloc", lambda shape: np.full(shape, np.nan))


@pytest.fixture
def one_blas_thread() -> Iterator[None]:
    """This process on one BLAS thread, as kinecal's worker processes are (and the
    kinecal command): serial and parallel runs then sum in the same order to the last
    digit. The previous thread count is restored."""
    from kinecal._parallel import blas_threads, set_blas_threads

    before = blas_threads()
    set_blas_threads(1)
    try:
        yield
    finally:
        if before:
            set_blas_threads(before[0])


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(20240416)


@pytest.fixture
def run_cli() -> Callable[..., subprocess.CompletedProcess[str]]:
    def run(
        *args: str, cwd: str | None = None, timeout: float = 600
    ) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [sys.executable, "-m", "kinecal", *args],
            capture_output=True,
            text=True,
            cwd=cwd,
            timeout=timeout,
        )

    return run
