"""The certificate fields of a calibration (issue 38 point 3): the user's ``--meta
key=value`` pairs (robot serial, instrument and its certificate, operator, site, ...)
and the temperature range of an optional ``temperature_c`` column of the data."""

from __future__ import annotations

import math
import re
import time
from typing import Any

from kinecal.report._format import e, num, table

__all__ = ["certificate_block", "certificate_html", "parse_meta", "temperature_range"]

_KEY = re.compile(r"^[A-Za-z][A-Za-z0-9_.-]{0,63}$")
# Outside this a temperature in degrees Celsius is not a workshop's (wrong unit, K or F).
_T_RANGE = (-40.0, 80.0)


def parse_meta(pairs: tuple[str, ...] | list[str]) -> dict[str, str]:
    """``("serial=R-123", "operator=J. Doe")`` -> a dict in the order given; ValueError
    naming the bad pair (no ``=``, a bad key, an empty value, a key given twice)."""
    out: dict[str, str] = {}
    for p in pairs:
        key, sep, value = p.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not _KEY.match(key) or not value:
            raise ValueError(
                f"expected key=value (key: letters, digits, _ . -; a value); got {p!r}."
            )
        if key in out:
            raise ValueError(f"key {key!r} given twice.")
        out[key] = value
    return out


def temperature_range(path: str, rows: Any) -> dict[str, Any] | None:
    """min / max / median of the ``temperature_c`` column over the rows used (None when
    the file has no such column); DataError naming the line of a value that is not a
    temperature in °C."""
    import numpy as np

    from kinecal._stats import median
    from kinecal.errors import DataError
    from kinecal.io import read_table

    try:  # a file without the word has no such column: not parsed a second time
        with open(path, "rb") as fh:
            if b"temperature_c" not in fh.read():
                return None
    except OSError:
        pass  # read_table names the problem
    t = read_table(path)
    if "temperature_c" not in t.header:
        return None
    k = t.header.index("temperature_c")
    by_line = dict(zip(t.lines, t.rows, strict=True))
    vals = []
    for r in rows:
        line = int(r)
        text = by_line[line][k].strip()
        try:
            v = float(text)
        except ValueError:
            v = math.nan
        if not math.isfinite(v) or not _T_RANGE[0] <= v <= _T_RANGE[1]:
            raise DataError(
                f"{path}: line {line}, column temperature_c: {text!r}; expected a "
                f"temperature in °C between {_T_RANGE[0]:g} and {_T_RANGE[1]:g}."
            )
        vals.append(v)
    a = np.asarray(vals)
    return {
        "min": float(a.min()),
        "max": float(a.max()),
        "median": median(a),
        "n": int(a.size),
    }


def certificate_block(
    meta: dict[str, str], temperature: dict[str, Any] | None
) -> dict[str, Any]:
    """report.json's ``certificate``."""
    out: dict[str, Any] = {
        "meta": dict(meta),
        "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    if temperature is not None:
        out["temperature_c"] = temperature
    return out


def certificate_html(summary: Any) -> str:
    """The certificate section (nothing without one)."""
    c = summary.get("certificate") if hasattr(summary, "get") else None
    if not c:
        return ""
    rows = [[e(k), e(v)] for k, v in (c.get("meta") or {}).items()]
    rows.append(["calibrated (UTC)", e(c.get("date_utc"))])
    t = c.get("temperature_c")
    if t:
        rows.append(
            [
                "temperature [°C]",
                f"{num(t['min'], 3)} – {num(t['max'], 3)} (median {num(t['median'], 3)},"
                f" {e(t['n'])} rows)",
            ]
        )
    else:
        rows.append(["temperature [°C]", "not recorded (no temperature_c column)"])
    return "<h2 id=certificate>Certificate</h2>" + table(
        ["field", "value"], rows, left=2
    )
