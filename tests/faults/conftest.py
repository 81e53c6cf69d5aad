"""The fault suite's shared data: one small tracker data set with its model (written by
kinecal itself), built once per session; tests copy what they change."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli_contract import make_point_data


@pytest.fixture(scope="session")
def data(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = make_point_data(tmp_path_factory.mktemp("faults"))
    # a targets file of sensor data (target, x_mm, y_mm, z_mm)
    (d["dir"] / "spheres.csv").write_text("target,x_mm,y_mm,z_mm\nA,1,2,3\nB,4,5,6\n")
    return d
