"""Run the CLI in a subprocess, as a user would."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable

import pytest


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
