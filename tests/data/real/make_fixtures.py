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
TIAGO = ROOT / "examples" / "data" / "tiago_figaroh_qualisys"


def tiago_points() -> str:
    """The TIAGo mocap file as point rows: markers 1-3 (marker 4 repeats 3) of every
    sample, the torso lift in mm, the arm joints in degrees, positions in mm."""
    import csv

    head = ["j1_mm", *(f"j{k}_deg" for k in range(2, 9)), "x_mm", "y_mm", "z_mm"]
    lines = [",".join([*head, "marker"])]
    with open(TIAGO / "qualysis_base_hand_calibration.csv", newline="") as f:
        for r in csv.DictReader(f):
            q = [float(r["torso_lift_joint"]) * 1e3]
            q += [np.degrees(float(r[f"arm_{k}_joint"])) for k in range(1, 8)]
            for m in (1, 2, 3):
                p = [float(r[f"{c}{m}"]) * 1e3 for c in "xyz"]
                lines.append(
                    ",".join(
                        [*(f"{v:.6f}" for v in q), *(f"{v:.4f}" for v in p), f"m{m}"]
                    )
                )
    return "\n".join(lines) + "\n"


def main() -> None:
    ur10, fr3 = load_robot("ur10e"), load_robot("franka-fr3")
    (HERE / "ur10_mocap.csv").write_text(measurements_to_csv(load_ur10(), ur10))
    m = load_fr3()
    a, b = m.subset(np.arange(60)), moved_board(m.subset(np.arange(60, m.n)))
    (HERE / "fr3_session_a.csv").write_text(measurements_to_csv(a, fr3))
    (HERE / "fr3_session_b_board_moved.csv").write_text(measurements_to_csv(b, fr3))
    (HERE / "tiago_mocap.csv").write_text(tiago_points())


if __name__ == "__main__":
    main()
