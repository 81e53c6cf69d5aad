"""Issue 36: the data checks of a large file cost little where their answer is clear
early, and say the same as the full check where it is not."""

from __future__ import annotations

import numpy as np

from kinecal.identification import Measurements
from kinecal.io import _checks, data_diagnostics
from kinecal.robot import RobotDescription, load_robot

FANUC = load_robot("fanuc-lrmate200id")


def _counted_fk(monkeypatch) -> list[int]:
    rows: list[int] = []
    fk = RobotDescription.fk_flange

    def counted(self, q, *a, **k):
        rows.append(int(np.shape(q)[0]))
        return fk(self, q, *a, **k)

    monkeypatch.setattr(RobotDescription, "fk_flange", counted)
    return rows


def _poses(rng, n: int, spread_deg: float) -> Measurements:
    q = np.radians([0.0, 10.0, -20.0, 0.0, -60.0, 0.0]) + np.radians(
        spread_deg
    ) * rng.uniform(-1, 1, (n, 6))
    return Measurements("point", q, FANUC.fk_flange(q)[:, :3, 3])


def test_issue_36_excitation_turns_few_rows_when_the_tool_turns(monkeypatch, rng):
    """2000 well spread poses: the orientation check's forward kinematics on a few
    rows (it was all 2000 + 1: 2.5 ms of a 2000-pose calibrate)."""
    meas = _poses(rng, 2000, 60.0)
    rows = _counted_fk(monkeypatch)
    found = _checks.excitation(meas, FANUC)
    assert found == []
    assert sum(rows) <= _checks._FEW_ROWS + 1


def test_issue_36_a_tool_that_hardly_turns_is_said_with_the_spread_of_all_rows(
    monkeypatch, rng
):
    """Below the limit, the few rows are only a first look: the message gives the
    spread of the whole sample, as before."""
    meas = _poses(rng, 3000, 0.8)
    full = _checks._orientation_spread_deg(meas, FANUC)
    rows = _counted_fk(monkeypatch)
    found = [d for d in data_diagnostics(meas, FANUC) if "orientation" in d.message]
    assert len(found) == 1 and f"within {full:.3g} deg" in found[0].message
    assert sum(rows) > 2000  # the few rows, then the whole sample
