"""report.json checked before it is drawn (``kinecal report DIR``).

The file is what ``kinecal calibrate`` wrote, or a hand-edited copy: with the run's
manifest.json its hash is checked (:func:`check_manifest`);
without one, a value that cannot be right would be drawn as it stands (an RMS of
``"big"``, a negative standard deviation). Every quantity is named by its unit suffix
(``_mm``, ``_deg``, ``_s``), or is a parameter's ``value``, ``std``, ``start`` or
``prior_std``, or a count ``n``: each must be a finite number (or null: not measured),
RMS values, standard deviations, maxima, percentiles, noise and counts not negative;
lists of them alike.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from kinecal.errors import DataError
from kinecal.io._json_read import loads

__all__ = ["check_manifest", "check_summary"]

_UNITS = ("_mm", "_deg", "_s", "_um")
_PARAMETER = ("value", "std", "start", "prior_std")
# Quantities that cannot be negative (by their name's start); the others (positions,
# offsets, angles, a parameter's value) may be.
_NOT_NEGATIVE: tuple[str, ...] = ("rms", "std", "se_", "max", "mean_mm", "p50")
_NOT_NEGATIVE += ("p95", "p99", "sigma", "noise", "radius", "prior_std")


def check_summary(doc: Any, path: Path) -> None:
    """Refuse a report.json whose quantities are not numbers (DataError naming the
    file and the field, e.g. ``after.rms_mm``)."""
    if not isinstance(doc, dict):
        raise DataError(
            f"{path}: expected a JSON object (report.json of kinecal calibrate)."
        )
    _walk(doc, "", path)


def _walk(node: Any, where: str, path: Path) -> None:
    if isinstance(node, dict):
        for key, value in node.items():
            name = f"{where}.{key}" if where else str(key)
            if _is_quantity(str(key)):
                _quantity(value, name, path, signed=not _not_negative(str(key)))
            else:
                _walk(value, name, path)
    elif isinstance(node, list):  # only containers hold quantities (names: lazily)
        for i, value in enumerate(node):
            if isinstance(value, (dict, list)):
                _walk(value, f"{where}[{i}]", path)


def _is_quantity(key: str) -> bool:
    return key == "n" or key in _PARAMETER or key.endswith(_UNITS)


def _not_negative(key: str) -> bool:
    if key == "n":  # a count
        return True
    return "signed" not in key and (key.startswith(_NOT_NEGATIVE) or "_rms" in key)


def _quantity(value: Any, name: str, path: Path, *, signed: bool) -> None:
    if isinstance(value, list):
        for i, v in enumerate(value):  # the element's name only for a message
            if isinstance(v, list) or not _fine(v, signed, False):
                _quantity(v, f"{name}[{i}]", path, signed=signed)
        return
    if not _fine(value, signed, name.rsplit(".", 1)[-1] == "n"):
        what = "a finite number" if signed else "a finite number >= 0"
        raise DataError(
            f"{path}: {name}: {str(value)[:40]!r} is not {what} (or null); expected "
            "the report.json kinecal calibrate wrote (draw the report from the run's "
            "own files, or run the calibration again)."
        )


def check_manifest(d: Path) -> None:
    """The folder's files against the SHA-256 its manifest.json recorded (a
    manifest without them, or none, is not checked): files of different runs are
    refused, naming the one that differs."""
    from kinecal.io import file_sha256
    from kinecal.report._poses import RESIDUALS_CSV

    try:
        doc = loads((d / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return
    outputs = doc.get("outputs") if isinstance(doc, dict) else None
    if not isinstance(outputs, dict):
        return
    for name in ("model.yaml", "report.json", RESIDUALS_CSV):
        want = outputs.get(name)
        f = d / name
        if isinstance(want, str) and f.is_file() and file_sha256(f) != want:
            raise DataError(
                f"{f}: is not the file its run wrote (its SHA-256 differs from the one "
                f"in {d / 'manifest.json'}); the folder mixes files of different runs. "
                "Expected the files of one `kinecal calibrate` run: run it again, or "
                "remove manifest.json to draw the report from these files anyway."
            )


def _fine(value: Any, signed: bool, count: bool) -> bool:
    """A quantity that is null, or a finite number (>= 0 unless ``signed``; an
    integer for a count)."""
    if value is None:
        return True
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    ok = number and math.isfinite(value) and (signed or value >= 0)
    return bool(ok and (isinstance(value, int) or not count))
