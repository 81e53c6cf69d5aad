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


def test_issue_36_as_read_is_what_read_pose_errors_reads(tmp_path):
    """calibrate draws its report from PoseErrors.as_read, not from parsing the file it
    has just written: the same numbers to the bit (ties at the 6th decimal, -0.0,
    values whose v·1e6 rounds near a half), the same layout."""
    rng = np.random.default_rng(7)
    n = 400
    halves = (rng.integers(-(10**9), 10**9, (n, 3)) + 0.5) / 1e6  # near-ties
    q = rng.normal(0, 90, (n, 6))
    q[::7, 0] = np.nextafter(halves[::7, 0], np.inf)
    pe = PoseErrors(
        row=np.arange(2, n + 2),
        q=q,
        joint_units=("deg",) * 5 + ("mm",),
        p_mm=halves,
        before_mm=rng.normal(0, 1, (n, 3)) * 10.0 ** rng.integers(-9, 3, (n, 1)),
        after_mm=np.where(rng.random((n, 3)) < 0.1, -0.0, rng.normal(0, 1e-6, (n, 3))),
    )
    path = tmp_path / "residuals.csv"
    path.write_text(pe.to_csv())
    read, mine = _poses.read_pose_errors(path), pe.as_read(path)
    for name in ("row", "q", "p_mm", "before_mm", "after_mm"):
        a, b = getattr(read, name), getattr(mine, name)
        assert a.dtype == b.dtype and a.strides == b.strides, name
        assert np.array_equal(a, b) and np.array_equal(np.signbit(a), np.signbit(b))
    assert read.joint_units == mine.joint_units
    x = np.concatenate([halves.ravel(), q.ravel(), pe.before_mm.ravel(), [np.inf]])
    want = [float(f"{v:.6f}") for v in x.tolist()]
    assert _poses._as_written(x).tolist() == want
    # more rows than the sample: read from the file, as a sample
    assert mine.total is None and pe.as_read(path, sample=50).total == n
