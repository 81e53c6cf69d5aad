"""The fuzz suite's Hypothesis settings and its mutations of valid inputs: CSV text,
YAML documents, lines.

Hypothesis runs derandomized (the same examples on every run, no example database), so
``make test`` stays deterministic and bounded (25 examples per test by default).
"""

from __future__ import annotations

import copy
import os
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

# KINECAL_FUZZ_EXAMPLES=500 KINECAL_FUZZ_RANDOM=1 searches wider (not in make test).
FUZZ = settings(
    max_examples=int(os.environ.get("KINECAL_FUZZ_EXAMPLES", "25")),
    derandomize=os.environ.get("KINECAL_FUZZ_RANDOM", "") in ("", "0"),
    database=None,
    deadline=None,
    print_blob=False,
    suppress_health_check=[
        HealthCheck.too_slow,
        HealthCheck.function_scoped_fixture,
        HealthCheck.data_too_large,
        HealthCheck.filter_too_much,
    ],
)

# Cell values a hand-edited or broken file holds.
ODD_CELLS = [
    "",
    " ",
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e400",
    "-1e400",
    "1e-400",
    "abc",
    '"',
    "0x10",
    "1_000",
    "--1",
    "+",
    "1,5",
    "١",
    "1e308",
    "-0",
    "99999999",
    "S9",
    "null",
]


def _csv_rows(text: str) -> list[list[str]]:
    return [ln.split(",") for ln in text.splitlines()]


def _csv_text(rows: list[list[str]]) -> str:
    return "\n".join(",".join(r) for r in rows) + "\n"


@st.composite
def mutated_csv(draw: st.DrawFn, text: str) -> bytes:
    """One to three mutations of a CSV file's text (cells, rows, columns, encoding)."""
    rows = _csv_rows(text)
    n_mut = draw(st.integers(1, 3))
    raw_tail = b""
    for _ in range(n_mut):
        kind = draw(
            st.sampled_from(
                [
                    "cell",
                    "cell",
                    "cell_text",
                    "drop_row",
                    "dup_row",
                    "drop_col",
                    "rename_col",
                    "dup_col",
                    "extra_col",
                    "short_row",
                    "long_row",
                    "identical_rows",
                    "header_only",
                    "truncate",
                    "blank_lines",
                    "semicolons",
                    "swap_cols",
                    "bytes",
                    "few_rows",
                ]
            )
        )
        nr = len(rows)
        if nr == 0:
            rows = [["j1_deg"]]
            nr = 1
        r = draw(st.integers(0, nr - 1))
        c = draw(st.integers(0, max(len(rows[r]) - 1, 0)))
        if kind == "cell" and rows[r]:
            rows[r][c] = draw(st.sampled_from(ODD_CELLS))
        elif kind == "cell_text" and rows[r]:
            rows[r][c] = draw(
                st.text(
                    st.characters(blacklist_characters=",\n\r", codec="utf-8"),
                    max_size=6,
                )
            )
        elif kind == "drop_row":
            del rows[r]
        elif kind == "dup_row":
            rows.insert(r, list(rows[r]))
        elif kind == "drop_col":
            rows = [row[:c] + row[c + 1 :] for row in rows]
        elif kind == "rename_col" and rows[0]:
            rows[0][min(c, len(rows[0]) - 1)] = draw(
                st.sampled_from(
                    ["j1_rad", "j7_deg", "x", "X_MM", "target", "set", "sigma_mm", "qw"]
                )
            )
        elif kind == "dup_col":
            rows = [[*row, row[c]] if c < len(row) else row for row in rows]
        elif kind == "extra_col":
            name = draw(st.sampled_from(["payload_kg", "sigma_mm", "note", "marker"]))
            val = draw(st.sampled_from(["1", "-1", "0", "x", "", "nan"]))
            rows = [rows[0] + [name]] + [[*row, val] for row in rows[1:]]
        elif kind == "short_row" and len(rows[r]) > 1:
            rows[r] = rows[r][:-1]
        elif kind == "long_row":
            rows[r] = rows[r] + ["1"]
        elif kind == "identical_rows" and nr > 1:
            rows = [rows[0]] + [list(rows[1]) for _ in rows[1:]]
        elif kind == "header_only":
            rows = rows[:1]
        elif kind == "few_rows":
            rows = rows[: draw(st.integers(1, 6))]
        elif kind == "truncate":
            t = _csv_text(rows)
            cut = draw(st.integers(0, len(t)))
            return t[:cut].encode()
        elif kind == "blank_lines":
            rows.insert(r, [""])
        elif kind == "semicolons":
            return _csv_text(rows).replace(",", ";").encode()
        elif kind == "swap_cols" and rows[0] and len(rows[0]) > 1:
            c1 = min(c, len(rows[0]) - 1)  # c counts the cells of row r (longer)
            c2 = draw(st.integers(0, len(rows[0]) - 1))
            rows[0][c1], rows[0][c2] = rows[0][c2], rows[0][c1]
        elif kind == "bytes":
            raw_tail = draw(st.binary(min_size=1, max_size=8))
    return _csv_text(rows).encode() + raw_tail


ODD_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["", "x", "deg", "mm", "full", "nan", "J1", "auto:full"]),
    st.lists(st.integers(-3, 9), max_size=4),
    st.dictionaries(
        st.sampled_from(["x", "r", "a", "joint"]), st.integers(), max_size=2
    ),
)


def _paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every path (keys and indices) into a nested dict/list document."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out += _paths(v, (*prefix, i))
    return out


@st.composite
def mutated_doc(draw: st.DrawFn, doc: Any) -> Any:
    """A document with one to three of its entries replaced, deleted, or added."""
    doc = copy.deepcopy(doc)
    for _ in range(draw(st.integers(1, 3))):
        paths = [p for p in _paths(doc) if p]
        if not paths:
            break
        path = draw(st.sampled_from(paths))
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        key = path[-1]
        kind = draw(st.sampled_from(["replace", "replace", "delete", "add", "scale"]))
        if kind == "replace":
            parent[key] = draw(ODD_VALUES)
        elif kind == "delete":
            del parent[key]
        elif kind == "add" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["extra", "a", "std", "unit"]))] = draw(
                ODD_VALUES
            )
        elif kind == "scale" and isinstance(parent[key], (int, float)):
            parent[key] = parent[key] * draw(st.sampled_from([-1, 0, 1e3, 1e-3]))
    return doc


@st.composite
def mutated_text(draw: st.DrawFn, text: str) -> str:
    """Line-level damage to a text file: a line duplicated (duplicate keys in YAML),
    dropped, or the file cut short."""
    lines = text.splitlines()
    kind = draw(st.sampled_from(["dup", "drop", "cut"]))
    i = draw(st.integers(0, max(len(lines) - 1, 0)))
    if kind == "dup" and lines:
        lines.insert(i, lines[i])
    elif kind == "drop" and lines:
        del lines[i]
    else:
        return text[: draw(st.integers(0, len(text)))]
    return "\n".join(lines) + "\n"
