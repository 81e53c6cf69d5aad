"""A CSV file with a header, read column-wise: numeric columns parsed in one pass.

The text is split into lines once; comment (``#``) and blank lines are dropped; the
numeric columns are converted together by numpy's C parser (:func:`numpy.loadtxt`), with
no Python object per cell. Only when that fails (a bad value, a quoted file, an unusual
spelling of a number that Python's ``float`` accepts) is the column read cell by cell,
which also finds the file line and the value for the message.
"""

from __future__ import annotations

import itertools
import operator
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from kinecal._record import ReprRecord
from kinecal.errors import DataError

__all__ = ["LABEL_COLUMNS", "Table", "read_table"]

# Columns that hold names, never parsed as numbers in the bulk pass.
LABEL_COLUMNS = frozenset({"set", "marker", "target", "name", "label", "point"})
# Line breaks that str.splitlines knows besides \n and \r: such a file takes the
# cell-by-cell path, which treats them exactly as before.
_ODD_BREAKS = "\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
# Characters of a file in which the header is looked for first.
_HEAD = 1 << 16
_FIRST = operator.itemgetter(slice(0, 1))  # a line's first character ('' if empty)


@dataclass(frozen=True, eq=False, repr=False)
class Table(ReprRecord):
    """A CSV file as text: header, data lines and the file line of each.

    Attributes
    ----------
    path : str
    header : list of str, the column names (stripped).
    data : list of str, the text of each data line (comments and blank lines dropped);
        empty for a file with quoted cells, whose cells are in ``rows``.
    lines : (N,) int, file line (1-based) of each data row.
    """

    path: str
    header: list[str]
    data: list[str]
    lines: np.ndarray
    _rows: list[list[str]] | None = field(default=None, repr=False)
    _numbers: dict[str, np.ndarray] = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return int(self.lines.shape[0])

    @property
    def rows(self) -> list[list[str]]:
        """The cells of every data row (built on first use; prefer :meth:`column`)."""
        if self._rows is None:
            object.__setattr__(self, "_rows", [s.split(",") for s in self.data])
        assert self._rows is not None
        return self._rows

    def row(self, i: int) -> list[str]:
        """The cells of data row ``i``."""
        return self._rows[i] if self._rows is not None else self.data[i].split(",")

    def column(self, name: str) -> list[str]:
        """The raw cells of a column, as written (not stripped)."""
        k = self.header.index(name)
        if self._rows is not None:
            return [r[k] for r in self._rows]
        return [s.split(",", k + 1)[k] for s in self.data]

    def numbers(self, name: str) -> np.ndarray:
        """Column ``name`` as floats, shape (N,); a non-number or a non-finite value is
        a :class:`DataError` naming the line, the column and the value."""
        if name not in self._numbers:
            self._parse(name)
        out = self._numbers[name]
        bad = np.flatnonzero(~np.isfinite(out))
        if bad.size:
            i = int(bad[0])
            s = self.row(i)[self.header.index(name)].strip()
            raise DataError(
                f"{self.path}: line {self.lines[i]}, column '{name}': expected a finite "
                f"number; got {s!r}."
            )
        return out

    # ------------------------------------------------------------------ parsing
    def _parse(self, name: str) -> None:
        if self._rows is None and not self._numbers:
            # First use: every column that is not a label, at once.
            cols = [c for c in self.header if c not in LABEL_COLUMNS]
            if name in cols and self._bulk(cols):
                return
        if self._rows is None and self._bulk([name]):
            return
        self._numbers[name] = self._cell_by_cell(name)

    def _bulk(self, cols: list[str]) -> bool:
        """Parse ``cols`` with numpy's C parser; False if any cell is not a plain number."""
        idx = [self.header.index(c) for c in cols]
        try:
            block = np.loadtxt(
                self.data,
                delimiter=",",
                comments=None,
                usecols=idx,
                dtype=np.float64,
                ndmin=2,
                quotechar=None,
            )
        except ValueError:
            return False
        for j, c in enumerate(cols):
            self._numbers[c] = np.ascontiguousarray(block[:, j])
        return True

    def _cell_by_cell(self, name: str) -> np.ndarray:
        k = self.header.index(name)
        rows = self.rows
        try:  # Python's float reads a few spellings numpy's parser does not
            return np.array([r[k] for r in rows], dtype=np.float64)
        except ValueError:
            pass
        for r, line in zip(rows, self.lines):
            s = r[k].strip()
            try:
                float(s)
            except ValueError:
                comma = re.fullmatch(r"[-+]?\d*,\d+", s)  # "1,5" quoted between commas
                hint = (
                    " (a decimal comma: write 1.5, or ';' between cells)"
                    if comma
                    else ""
                )
                raise DataError(
                    f"{self.path}: line {line}, column '{name}': expected a number; "
                    f"got {s!r}{hint}."
                ) from None
        raise AssertionError(
            "unreachable: a cell failed, then none did"
        )  # pragma: no cover


def _read_text(p: Path) -> str:
    try:
        return p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise DataError(f"{p}: file not found.") from None
    except IsADirectoryError:
        raise DataError(f"{p}: is a folder, not a CSV file.") from None
    except OSError as exc:
        raise DataError(f"{p}: cannot read ({exc.strerror}).") from None
    except UnicodeDecodeError as exc:
        raise DataError(_not_utf8(p, exc)) from None


def _not_utf8(p: Path, exc: UnicodeDecodeError) -> str:
    """What is wrong with a CSV that is not UTF-8, naming its line: UTF-16 (Excel's
    "Unicode text"), or a byte of another 8-bit encoding (Latin-1, Windows-1252)."""
    raw = p.read_bytes()
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff") or b"\0" in raw[:4096]:
        return (
            f"{p}: UTF-16 encoded (or binary): not a text (UTF-8) CSV file; expected "
            "UTF-8 (save it as 'CSV UTF-8')."
        )
    line = raw.count(b"\n", 0, exc.start) + 1
    return (
        f"{p}: line {line}: byte 0x{raw[exc.start]:02x} is not UTF-8 (a Latin-1 or "
        "Windows-1252 file?): not a text (UTF-8) CSV file; expected UTF-8 (save it as "
        "'CSV UTF-8')."
    )


def _comma_separated(text: str) -> str:
    """The text with commas between cells: a file whose header has no comma but
    semicolons (a spreadsheet in a decimal-comma locale: its commas are decimal
    points) or tabs is read as well."""
    # the lines of a first part of the text (its last one may be cut: not looked at),
    # or of all of it (splitting the whole text took 0.4 ms of a 2000-row file)
    head = text[:_HEAD].splitlines()[:-1] if len(text) > _HEAD else []
    first = next(
        (s for s in head if s.strip() and not s.lstrip().startswith("#")), None
    )
    if first is None:
        first = next(
            (
                s
                for s in text.splitlines()
                if s.strip() and not s.lstrip().startswith("#")
            ),
            "",
        )
    if "," in first:
        return text
    for sep in (";", "\t"):
        if sep in first:
            if sep == ";" or "." not in text:
                text = text.replace(",", ".")  # decimal commas
            return text.replace(sep, ",")
    return text


def _is_skipped(s: str) -> bool:
    """A comment line (first cell starts with '#') or a line of blank cells."""
    t = s.lstrip()
    return not t or t[0] == "#" or (t[0] == "," and not t.replace(",", "").strip())


def _header(p: Path, cells: list[str], lineno: int) -> list[str]:
    header = [c.strip() for c in cells]
    dup = {c for c in header if header.count(c) > 1}
    if dup:
        raise DataError(f"{p}: line {lineno}: duplicate column {sorted(dup)[0]!r}.")
    return header


def read_table(path: str | Path) -> Table:
    """Read a CSV file with a header; lines whose first cell starts with '#' are
    comments, lines of blank cells are skipped. Cells are separated by commas, or by
    semicolons (then a comma is a decimal point) or tabs when the header has no comma.

    Raises
    ------
    DataError
        Missing or unreadable file, no header, no data rows, duplicate column names, a
        row with a different number of values than the header (naming its line).
    """
    from kinecal._outputs import note_input

    note_input(path)
    p = Path(path)
    text = _comma_separated(_read_text(p))
    if '"' in text or any(c in text for c in _ODD_BREAKS):
        return _read_quoted(p, text)
    all_lines = text.splitlines()
    # Comments and blank lines start with '#', a comma or white space (or are empty):
    # the first characters of the lines, taken and looked at without a Python loop.
    firsts = "".join(map(_FIRST, all_lines))
    clean = (
        "#" not in text
        and len(firsts) == len(all_lines)  # no empty line
        and "," not in firsts
        and len("".join(firsts.split())) == len(firsts)  # none is white space
    )
    if clean:
        numbers = np.arange(1, len(all_lines) + 1, dtype=np.intp)
        kept = all_lines
    else:  # drop comments and blank lines, remembering the file line of each kept one
        keep = [i for i, s in enumerate(all_lines) if not _is_skipped(s)]
        numbers = np.asarray(keep, dtype=np.intp) + 1
        kept = [all_lines[i] for i in keep]
    if not kept:
        raise DataError(f"{p}: the file is empty (a header line is required).")
    header = _header(p, kept[0].split(","), int(numbers[0]))
    data, lines = kept[1:], numbers[1:]
    if not data:
        raise DataError(f"{p}: no data rows after the header.")
    commas = np.fromiter(
        map(str.count, data, itertools.repeat(",")), np.intp, len(data)
    )
    bad = np.flatnonzero(commas != len(header) - 1)
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{p}: line {lines[i]}: {commas[i] + 1} values for {len(header)} columns."
        )
    return Table(str(p), header, data, lines)


def _read_quoted(p: Path, text: str) -> Table:
    """A file with quoted cells (or unusual line breaks): the csv module, row by row."""
    import csv

    header: list[str] | None = None
    rows: list[list[str]] = []
    lines: list[int] = []
    for lineno, row in enumerate(csv.reader(text.splitlines()), start=1):
        if (
            not row
            or all(not c.strip() for c in row)
            or row[0].lstrip().startswith("#")
        ):
            continue
        if header is None:
            header = _header(p, row, lineno)
            continue
        if len(row) != len(header):
            raise DataError(
                f"{p}: line {lineno}: {len(row)} values for {len(header)} columns."
            )
        rows.append(row)
        lines.append(lineno)
    if header is None:
        raise DataError(f"{p}: the file is empty (a header line is required).")
    if not rows:
        raise DataError(f"{p}: no data rows after the header.")
    return Table(str(p), header, [], np.asarray(lines, dtype=np.intp), rows)
