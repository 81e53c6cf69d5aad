"""Shared fixtures: a seeded random generator (never global np.random) and the CLI
run in a subprocess, as a user would."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable

import numpy as np
import pytest


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
