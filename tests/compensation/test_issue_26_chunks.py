"""Issue 26: a large program is compensated by chunks of targets, with the numbers of
one solve (every target is solved on its own), unreachable rows and all."""

from __future__ import annotations

import numpy as np

from kinecal.compensation import _compensate, compensate
from tests.compensation.conftest import box_poses


def test_issue_26_chunks_give_the_rows_of_one_solve(tracker_twin, monkeypatch):
    rng = np.random.default_rng(26)
    q = box_poses(rng, 40)
    p, _ = tracker_twin.truth.evaluate(q)
    p[[5, 17]] += [3.0, 0.0, 0.0]  # out of reach
    seed = q + np.radians(0.2) * rng.standard_normal(q.shape)
    whole = compensate(tracker_twin.calibrated, p, seed)
    monkeypatch.setattr(_compensate, "CHUNK", 7)
    chunks = compensate(tracker_twin.calibrated, p, seed)
    for field in _compensate._ROW_FIELDS:
        np.testing.assert_array_equal(getattr(chunks, field), getattr(whole, field))
    assert chunks.iterations == whole.iterations
    assert list(whole.status[[5, 17]]) == ["unreachable", "unreachable"]
