"""Shared fixtures: a seeded random generator (never global np.random), the CLI run in a
subprocess, as a user would, the model's Jacobian storage poisoned with NaN, and the
choice of the model's code (compiled kernel or numpy)."""

from __future__ import annotations

import os
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


def require_compiled_kernel() -> None:
    """Skip a test of the compiled kernel where it is not built (an installation without
    a C compiler), unless KINECAL_REQUIRE_KERNEL=1 (CI) makes that a failure."""
    from kinecal.models import compiled_kernel_available

    if compiled_kernel_available():
        return
    if os.environ.get("KINECAL_REQUIRE_KERNEL") == "1":
        pytest.fail("the compiled kernel is not built, and KINECAL_REQUIRE_KERNEL=1")
    pytest.skip("the compiled kernel is not built (no C compiler at install time)")


@pytest.fixture(params=["c", "numpy"])
def kernel(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Run the test with the compiled kernel, then with the numpy code."""
    if request.param == "c":
        require_compiled_kernel()
    monkeypatch.setenv("KINECAL_KERNEL", request.param)
    return str(request.param)


@pytest.fixture
def numpy_kernel(monkeypatch: pytest.MonkeyPatch) -> None:
    """The model's numpy code, for tests of what only it has (the kept forward state)."""
    monkeypatch.setenv("KINECAL_KERNEL", "numpy")


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
