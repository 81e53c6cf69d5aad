"""Regenerate the real-data fixtures from examples/data (run from the repository root).

.venv/bin/python tests/data/real/make_fixtures.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "examples"))

from franka_fr3_camera import load as load_fr3  # noqa: E402
from franka_fr3_camera import moved_board  # noqa: E402
from kinecal.io import measurements_to_csv  # noqa: E402
from kinecal.robot import load_robot  # noqa: E402
from ur10_mocap import load as load_ur10  # noqa: E402

HERE = Path(__file__).resolve().parent


def main() -> None:
    ur10, fr3 = load_robot("ur10e"), load_robot("franka-fr3")
    (HERE / "ur10_mocap.csv").write_text(measurements_to_csv(load_ur10(), ur10))
    m = load_fr3()
    a, b = m.subset(np.arange(60)), moved_board(m.subset(np.arange(60, m.n)))
    (HERE / "fr3_session_a.csv").write_text(measurements_to_csv(a, fr3))
    (HERE / "fr3_session_b_board_moved.csv").write_text(measurements_to_csv(b, fr3))


if __name__ == "__main__":
    main()
