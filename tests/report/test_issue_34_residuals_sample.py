"""``kinecal report`` on a large run reads a sample of residuals.csv (issue 34, small
items): the same rows and norms as reading the whole file and sampling it, a few MB
of the file at a time; a malformed line still named."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.errors import DataError
from kinecal.report import PoseErrors, _poses, read_pose_errors


def _file(tmp_path, n=5000):
    rng = np.random.default_rng(7)
    pe = PoseErrors(
        row=np.arange(1, n + 1),
        q=rng.uniform(-90, 90, (n, 6)),
        joint_units=("deg",) * 5 + ("mm",),
        p_mm=rng.uniform(-500, 500, (n, 3)),
        before_mm=rng.normal(0, 1, (n, 3)),
        after_mm=rng.normal(0, 0.05, (n, 3)),
    )
    path = tmp_path / "residuals.csv"
    path.write_text(pe.to_csv())
    return path


def test_sampled_read_is_the_sample_of_the_whole_file(tmp_path, monkeypatch):
    path = _file(tmp_path)
    monkeypatch.setattr(_poses, "_CHUNK", 20000)  # many chunks
    full = read_pose_errors(path)
    got = read_pose_errors(path, sample=300)
    want = full.sample(300)
    assert got.n == 300 and got.total == full.n
    for name in ("row", "q", "p_mm", "before_mm", "after_mm"):
        np.testing.assert_array_equal(getattr(got, name), getattr(want, name))
    assert got.joint_units == full.joint_units
    np.testing.assert_array_equal(got.all_after, np.linalg.norm(full.after_mm, axis=1))
    np.testing.assert_array_equal(
        got.all_before, np.linalg.norm(full.before_mm, axis=1)
    )
    small = read_pose_errors(path, sample=10**6)  # fewer rows than the sample
    assert small.n == full.n and small.total is None


@pytest.mark.parametrize(
    ("line", "message"),
    [
        (4000, r"line 4000, column 'ex_mm': not a finite number"),
        (17, r"residuals.csv: line 17: 'x1' is not a number"),
        (23, r"residuals.csv: line 23: 17 values; expected 18"),  # a ragged line
    ],
)
def test_sampled_read_names_a_malformed_line(tmp_path, line, message):
    path = _file(tmp_path)
    lines = path.read_text().split("\n")
    cells = lines[line - 1].split(",")
    if line == 4000:  # an error column: every row's is read
        cells[13] = "nan"
    elif line == 17:
        cells[10] = "x1"
    else:
        cells.pop()
    lines[line - 1] = ",".join(cells)
    path.write_text("\n".join(lines))
    with pytest.raises(DataError, match=message):
        read_pose_errors(path, sample=300)


@pytest.mark.parametrize("trailing", [True, False])
def test_a_file_of_at_most_the_sample_is_parsed_once(tmp_path, monkeypatch, trailing):
    """Issue 36: a file of no more rows than the sample is read whole at once (its line
    ends counted first; the sampling pass parsed it for nothing); one row more, with or
    without a final line end, is sampled as before."""
    path = _file(tmp_path, n=301)
    if not trailing:
        path.write_text(path.read_text().rstrip("\n"))
    monkeypatch.setattr(_poses, "_CHUNK", 1000)  # the count stops across chunks
    full = read_pose_errors(path)
    got = read_pose_errors(path, sample=300)
    assert got.n == 300 and got.total == 301
    np.testing.assert_array_equal(got.row, full.sample(300).row)
    calls = []
    real = np.loadtxt
    monkeypatch.setattr(np, "loadtxt", lambda *a, **k: calls.append(1) or real(*a, **k))
    whole = read_pose_errors(path, sample=301)
    assert whole.n == 301 and whole.total is None and len(calls) == 1
