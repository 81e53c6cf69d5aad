"""Inputs of the fault-proof fuzz suite (issue 21): a small data set, model and targets
written by kinecal itself, for the tests to mutate. The contract every run must keep is
in tests/cli_contract.py; the Hypothesis settings and mutations in strategies.py.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_contract import make_point_data


@pytest.fixture(scope="session")
def point_data(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A small laser-tracker data set, its model, test rows and compensation targets."""
    return make_point_data(tmp_path_factory.mktemp("fuzz-point"))
