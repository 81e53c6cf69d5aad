"""residuals.csv is written by one %-format per block of rows: the text numpy.savetxt
writes, row by row, for the same numbers (issue 36, point 4)."""

from __future__ import annotations

import io

import numpy as np

from kinecal.report import _poses
from kinecal.report._poses import PoseErrors


def _savetxt(pe: PoseErrors) -> str:
    head = ["row"] + [f"j{k + 1}_{u}" for k, u in enumerate(pe.joint_units)]
    data = np.column_stack(
        [
            pe.row,
            pe.q,
            pe.p_mm,
            pe.before_mm,
            pe.after_mm,
            np.linalg.norm(pe.before_mm, axis=1),
            np.linalg.norm(pe.after_mm, axis=1),
        ]
    )
    buf = io.StringIO()
    fmt = ["%d"] + ["%.6f"] * (data.shape[1] - 1)
    np.savetxt(
        buf,
        data,
        fmt=fmt,
        delimiter=",",
        header=",".join(head + _poses._TAIL),
        comments="",
    )
    return buf.getvalue()


def test_residuals_csv_is_the_text_savetxt_writes(monkeypatch):
    rng = np.random.default_rng(3)
    n = 57
    pe = PoseErrors(
        row=np.arange(2, n + 2),
        q=rng.normal(0, 90, (n, 6)),
        joint_units=("deg",) * 5 + ("mm",),
        p_mm=rng.normal(0, 500, (n, 3)),
        before_mm=rng.normal(0, 1, (n, 3)) * 10.0 ** rng.integers(-9, 3, (n, 1)),
        after_mm=np.where(rng.random((n, 3)) < 0.1, -0.0, rng.normal(0, 1e-3, (n, 3))),
    )
    monkeypatch.setattr(_poses, "_BLOCK", 10)  # several blocks, a short last one
    text = pe.to_csv()
    assert text == _savetxt(pe)
    assert text.count("\n") == n + 1
