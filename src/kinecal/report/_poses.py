"""Per-pose errors of a calibration: ``residuals.csv`` in the result folder.

``kinecal calibrate`` writes it beside ``model.yaml`` and ``report.json`` so that the
HTML report is a function of the folder's files alone (``kinecal report DIR``). One row
per measurement, in the order of the data file:

``row`` (line of the data file), ``j1_deg .. jN_deg`` (controller angles; ``jK_mm`` for
prismatic joints), ``x_mm, y_mm, z_mm`` (the reference point in the user frame: the
measured point for tracker data, the target's known centre for sensor data), the
position error model − measurement along x, y, z of the user frame before
(``ex_before_mm`` ...: nominal kinematics with fitted user and tool frames) and after
calibration (``ex_mm`` ...), and their norms ``err_before_mm``, ``err_mm``. The sign
and columns of ``ex_mm .. err_mm`` are those of ``kinecal evaluate --errors-out``.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from kinecal._numtext import csv_lines
from kinecal._record import Record
from kinecal.errors import DataError
from kinecal.typing import Float, Int

__all__ = [
    "FIGURE_POSES",
    "RESIDUALS_CSV",
    "PoseErrors",
    "pose_errors",
    "read_pose_errors",
]

RESIDUALS_CSV = "residuals.csv"
_TAIL = [
    "x_mm",
    "y_mm",
    "z_mm",
    "ex_before_mm",
    "ey_before_mm",
    "ez_before_mm",
    "ex_mm",
    "ey_mm",
    "ez_mm",
    "err_before_mm",
    "err_mm",
]
_JOINT = re.compile(r"j(\d+)_(deg|mm)$")


# Rows of residuals.csv formatted at once.
_BLOCK = 20000
# Poses drawn in the report's per-pose figures at most (a sample of larger runs).
FIGURE_POSES = 20000


@dataclass(frozen=True, eq=False, repr=False)
class PoseErrors(Record):
    """Per-pose data of a calibration (file units).

    Attributes
    ----------
    row : (N,) line of each measurement in the data file.
    q : (N, J) controller joint values [deg; mm for prismatic joints].
    joint_units : (J,) 'deg' or 'mm' per joint.
    p_mm : (N, 3) reference point in the user frame [mm].
    before_mm, after_mm : (N, 3) position error (model − measurement) in the user frame
        before and after calibration [mm].
    """

    row: Int
    q: Float
    joint_units: tuple[str, ...]
    p_mm: Float
    before_mm: Float
    after_mm: Float
    # A sample read from a larger file (read_pose_errors(path, sample=n)): how many
    # rows the file holds and every row's error norms before and after [mm].
    total: int | None = None
    all_before: Float | None = None
    all_after: Float | None = None

    @property
    def n(self) -> int:
        return int(self.row.shape[0])

    def sample(self, n: int = FIGURE_POSES) -> PoseErrors:
        """At most ``n`` of the poses, in their order, the same every time: the 1 % of
        ``n`` with the largest errors after calibration and poses evenly spaced through
        the data for the rest (all of them when there are ``n`` or fewer)."""
        if self.n <= n:
            return self
        i = _sample_index(np.einsum("ij,ij->i", self.after_mm, self.after_mm), n)
        return PoseErrors(
            row=self.row[i],
            q=self.q[i],
            joint_units=self.joint_units,
            p_mm=self.p_mm[i],
            before_mm=self.before_mm[i],
            after_mm=self.after_mm[i],
        )

    def to_csv(self) -> str:
        """The text of ``residuals.csv`` (6 decimals: 1 nm, 1 µdeg)."""
        return "".join(self.csv_blocks())

    def csv_blocks(self) -> Iterator[str]:
        """:meth:`to_csv` in blocks of rows (the header first), for writing a large
        file without holding its whole text."""
        yield ",".join(self._header()) + "\n"
        # The text of one %-format per block of rows (numpy.savetxt formats row by row
        # in Python, 3x slower), built as arrays of digits (kinecal._numtext: 3x faster
        # again); % itself for a block with values the arrays do not hold.
        line = ",".join(["%d"] + ["%.6f"] * (self.q.shape[1] + 11)) + "\n"
        for i in range(0, self.row.shape[0], _BLOCK):
            b = slice(i, i + _BLOCK)
            text = csv_lines(self.row[b], self._columns(b, with_row=False))
            if text is None:
                data = self._columns(b)
                text = (line * data.shape[0]) % tuple(data.ravel().tolist())
            yield text

    def as_read(self, path: str | Path, sample: int | None = None) -> PoseErrors:
        """``read_pose_errors(path, sample)`` of the residuals.csv :meth:`to_csv`
        wrote to ``path`` (every value rounded to its 6 decimals), without parsing the
        file (``kinecal calibrate`` draws its report from it: 7 ms less for 2000
        poses); more than ``sample`` rows are read from the file, as a sample."""
        if sample is not None and self.n > sample:
            return read_pose_errors(path, sample=sample)
        a = _as_written(self._columns(slice(None)))
        return _table(Path(path), a, self._header(), np.arange(self.n) + 2)

    def _header(self) -> list[str]:
        return (
            ["row"] + [f"j{k + 1}_{u}" for k, u in enumerate(self.joint_units)] + _TAIL
        )

    def _columns(self, b: slice, with_row: bool = True) -> Float:
        """The rows ``b`` of residuals.csv as numbers (before rounding); without the
        first column (``row``) when not ``with_row``."""
        return np.column_stack(
            [
                *([self.row[b]] if with_row else []),
                self.q[b],
                self.p_mm[b],
                self.before_mm[b],
                self.after_mm[b],
                np.linalg.norm(self.before_mm[b], axis=1),
                np.linalg.norm(self.after_mm[b], axis=1),
            ]
        )


def pose_errors(result, meas) -> PoseErrors:
    """The per-pose errors of a :class:`~kinecal.identification.CalibrationResult` on
    its calibration data ``meas`` (Measurements)."""
    from kinecal.measurement import Weights, residuals

    cal = result.calibrated
    m = cal.model
    inputs = meas.model_inputs(cal.reference_payload_kg)
    # Every row of the data, the rejected ones too (raw errors need no weights).
    w = Weights.default(meas)
    # The fit's own evaluations where they are of these rows and inputs (its cache
    # keeps the raw errors at the registered point and the solution: no pass).
    ws = getattr(result, "workspace", None)
    if (
        ws is not None
        and ws.meas is meas
        and np.array_equal(ws.inputs.load_scale, inputs.load_scale)
    ):
        before = ws.evaluations(m, result.registered, w)
        after = ws.evaluations(m, cal.params, w)
    else:
        before = residuals(m, result.registered, meas, w, inputs=inputs)
        after = residuals(m, cal.params, meas, w, inputs=inputs)
    prismatic = np.array([j.kind == "prismatic" for j in m.robot.joints])
    rows = meas.rows if meas.rows.size == meas.n else np.arange(meas.n)
    return PoseErrors(
        row=np.asarray(rows, np.intp),
        q=meas.q_ctrl * np.where(prismatic, 1e3, 180.0 / np.pi),
        joint_units=tuple("mm" if p else "deg" for p in prismatic),
        p_mm=meas.reference_points() * 1e3,
        before_mm=before.raw_position * 1e3,
        after_mm=after.raw_position * 1e3,
    )


def _as_written(x: Float) -> Float:
    """``float('%.6f' % v)`` of every value, without the text: ``k / 1e6`` for the
    integer k nearest to ``v·1e6`` is that number (a correctly rounded quotient of
    exact numbers) wherever ``v·1e6`` lies farther than its own rounding error from a
    half; the rest (such halves, non-finite or huge values) go through the text."""
    y = x * 1e6
    k = np.rint(y)
    out = k / 1e6
    with np.errstate(invalid="ignore"):
        a = np.abs(y)
        clear = (np.abs(np.abs(y - k) - 0.5) > 4 * np.spacing(a)) & (a < 2.0**52)
    if not clear.all():
        out[~clear] = [float(f"{v:.6f}") for v in x[~clear].tolist()]
    return out


def _sample_index(err: Float, n: int) -> Int:
    """The rows :meth:`PoseErrors.sample` keeps of N > n rows of squared errors
    after calibration ``err`` (N,) [mm²]."""
    N = err.shape[0]
    top = max(n // 100, 1)
    worst = np.argpartition(err, N - top)[N - top :]
    keep = np.zeros(N, bool)
    keep[worst] = True
    rest = np.flatnonzero(~keep)
    keep[rest[np.linspace(0, rest.size - 1, n - top).round().astype(np.intp)]] = True
    return np.flatnonzero(keep)


# Bytes of lines parsed at once when a large file is sampled.
_CHUNK = 1 << 22


def _chunks(p: Path) -> Iterator[list[bytes]]:
    with open(p, "rb") as fh:
        fh.readline()
        while lines := fh.readlines(_CHUNK):
            yield lines


def _rows_at_most(p: Path, n: int) -> bool:
    """Whether the file has at most ``n`` lines after its header, by its line ends
    alone (never fewer than its rows; a few ms for 1e6 rows, stopping beyond ``n``)."""
    count, last = 0, b"\n"
    with open(p, "rb") as fh:
        fh.readline()
        while block := fh.read(_CHUNK):
            count, last = count + block.count(b"\n"), block[-1:]
            if count > n:
                return False
    return count + (last != b"\n") <= n


def _read_sampled(p: Path, head: list[str], n: int) -> PoseErrors | None:
    """A file of more than ``n`` rows read as :meth:`PoseErrors.sample` of it: a first
    pass parses only the six error columns (the sample's choice, every row's norms),
    a second the rows kept; a few MB at a time, never the whole file. None: the file
    has ``n`` rows or fewer, or a malformed line (the whole read names it)."""
    if _rows_at_most(p, n):
        return None  # read whole: a first pass would parse every row for nothing
    cols = [head.index(c) for c in _TAIL[3:9]]
    commas = len(head) - 1
    parts: list[Float] = []  # per chunk: norm before, norm after, squared after
    try:
        for lines in _chunks(p):
            if sum(ln.count(b",") for ln in lines) != commas * len(lines):
                return None
            e = np.loadtxt(lines, delimiter=",", usecols=cols, ndmin=2)
            if not np.all(np.isfinite(e)) or (np.abs(e) > 1e6).any():
                return None
            sq = np.einsum("ij,ij->i", e[:, 3:], e[:, 3:])
            parts.append(np.stack([np.linalg.norm(e[:, :3], axis=1),
                                   np.linalg.norm(e[:, 3:], axis=1), sq]))  # fmt: skip
    except ValueError:
        return None
    norms = np.concatenate(parts, axis=1) if parts else np.zeros((3, 0))
    del parts
    if norms.shape[1] <= n:
        return None
    idx = _sample_index(norms[2], n)
    rows, at = [], 0
    for lines in _chunks(p):
        k = idx[(idx >= at) & (idx < at + len(lines))] - at
        rows += [lines[j] for j in k]
        at += len(lines)
    a = np.loadtxt(rows, delimiter=",", ndmin=2)
    out = _table(p, a, head, idx + 2)
    return replace(
        out, total=int(norms.shape[1]), all_before=norms[0], all_after=norms[1]
    )


def read_pose_errors(path: str | Path, sample: int | None = None) -> PoseErrors:
    """Read a ``residuals.csv`` written by :meth:`PoseErrors.to_csv`; ``sample``: at
    most that many rows, :meth:`PoseErrors.sample` of a larger file read without
    holding it (with ``total`` and every row's error norms).

    Raises
    ------
    DataError
        Missing columns or values that are not numbers (the message names the file, and
        the column or line).
    """
    p = Path(path)
    try:
        with open(p, encoding="utf-8-sig") as fh:  # a byte-order mark is fine
            first = fh.readline()
    except FileNotFoundError:
        raise DataError(f"{p}: file not found.") from None
    except UnicodeDecodeError:
        raise DataError(f"{p}: not a UTF-8 text file.") from None
    head = first.strip().split(",")
    joints = [
        (int(m.group(1)), m.group(2), i)
        for i, c in enumerate(head)
        if (m := _JOINT.match(c))
    ]
    need = ["row", *_TAIL]
    missing = [c for c in need if c not in head]
    if missing or not joints:
        what = f"column '{missing[0]}'" if missing else "joint columns j1_deg .."
        raise DataError(
            f"{p}: missing {what}; expected the columns row, j1_deg .., {', '.join(_TAIL)}."
        )
    if sample is not None and (got := _read_sampled(p, head, sample)) is not None:
        return got
    try:
        # From the file (numpy reads it in chunks): a 1e6-row file's text, held as a
        # str and a StringIO, took 0.7 GB.
        a = np.loadtxt(p, delimiter=",", skiprows=1, ndmin=2, encoding="utf-8")
    except ValueError as exc:
        bad = _bad_line(p, head)
        raise DataError(bad or f"{p}: {exc}".replace("\n", " ")) from None
    return _table(p, a, head, np.arange(a.shape[0]) + 2)


def _bad_line(p: Path, head: list[str]) -> str | None:
    """The message for the first line of a residuals file that is not a number per
    column of ``head`` (after a failed read: numpy's own text counts rows its way)."""
    width = len(head)
    with open(p, encoding="utf-8", errors="replace") as fh:
        next(fh, None)
        for line_no, line in enumerate(fh, start=2):
            if not line.strip():
                continue
            cells = line.rstrip("\r\n").split(",")
            if len(cells) != width:
                return (
                    f"{p}: line {line_no}: {len(cells)} values; expected {width}, as "
                    "the header has."
                )
            for name, cell in zip(head, cells):
                try:
                    float(cell)
                except ValueError:
                    return (
                        f"{p}: line {line_no}: {cell.strip()[:40]!r} is not a number "
                        f"(column '{name}'); expected a number in every column."
                    )
    return None


def _table(p: Path, a: Float, head: list[str], lines: Int) -> PoseErrors:
    """The rows ``a`` of a residuals file (their file ``lines``), checked."""
    joints = sorted(
        (int(m.group(1)), m.group(2), i)
        for i, c in enumerate(head)
        if (m := _JOINT.match(c))
    )
    if a.shape[1] != len(head):
        raise DataError(
            f"{p}: {a.shape[1]} values per line; the header has {len(head)}."
        )
    if not np.all(np.isfinite(a)):
        r, c = np.argwhere(~np.isfinite(a))[0]
        raise DataError(
            f"{p}: line {lines[r]}, column '{head[c]}': not a finite number."
        )
    col = {c: i for i, c in enumerate(head)}
    huge = np.abs(a) > 1e6  # beyond 1 km or 1e6 deg: not data (and not drawable)
    huge[:, col["row"]] = False
    if huge.any():
        r, c = np.argwhere(huge)[0]
        raise DataError(
            f"{p}: line {lines[r]}, column '{head[c]}': {a[r, c]:g}; expected a value "
            "within 1e6 (mm or deg)."
        )
    rows = a[:, col["row"]]
    bad = np.flatnonzero((rows != np.round(rows)) | (np.abs(rows) > 2**31))
    if bad.size:
        raise DataError(
            f"{p}: line {lines[bad[0]]}, column 'row': expected a row number; got "
            f"{rows[bad[0]]:g}."
        )

    def take(*names: str) -> Float:
        return a[:, [col[n] for n in names]]

    return PoseErrors(
        row=rows.astype(np.intp),
        q=a[:, [i for _, _, i in joints]],
        joint_units=tuple(u for _, u, _ in joints),
        p_mm=take("x_mm", "y_mm", "z_mm"),
        before_mm=take("ex_before_mm", "ey_before_mm", "ez_before_mm"),
        after_mm=take("ex_mm", "ey_mm", "ez_mm"),
    )
