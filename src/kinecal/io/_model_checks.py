"""Checks of a model file's fields beside the values' physical bounds
(:mod:`._model_bounds`): the texts kinecal prints back (``kinecal_version``,
``info.source``), each parameter's ``std`` against its ``status``, and the robot
fingerprint as written.

A hand-edited file is input like any other: a ``std`` beside status
``unidentifiable`` or ``fixed`` (parameters the data did not determine: kinecal writes
null) claimed an uncertainty no fit gave; ``info.source`` given as a list or a
"billion laughs" alias was quoted in full in warnings.
"""

from __future__ import annotations

import re
from typing import Any

from kinecal.errors import ConfigError
from kinecal.models import CalibrationModel

__all__ = ["check_std", "check_text", "stamp_as_written"]

_STAMP = re.compile(
    r"^robot_sha256:[ \t]*['\"]?([0-9A-Za-z.+-]+)['\"]?[ \t]*(?:#.*)?$", re.M
)


def stamp_as_written(doc: Any, text: str) -> Any:
    """``doc`` with ``robot_sha256`` as the text of the file: a hexadecimal
    fingerprint such as ``1234e56789abcdef`` that an earlier kinecal wrote unquoted
    reads as a number in YAML 1.2 (the model file reads hand-typed ``1e-3`` as one)."""
    if isinstance(doc, dict) and isinstance(doc.get("robot_sha256"), (int, float)):
        if not isinstance(doc["robot_sha256"], bool):
            m = _STAMP.search(text)
            if m is not None:
                doc["robot_sha256"] = m.group(1)
    return doc


def check_text(doc: dict[str, Any], key: str, where: str, longest: int) -> None:
    """``doc[key]``, when present and not null, is one printable line of at most
    ``longest`` characters (a text kinecal prints back: a version, a file name)."""
    v = doc.get(key)
    if v is None:
        return
    ok = isinstance(v, str) and 0 < len(v) <= longest and v.isprintable()
    if not ok:
        shown = repr(v) if isinstance(v, str) else type(v).__name__
        raise ConfigError(
            f"{where}: {shown[:80]}; expected one line of text of at most {longest} "
            "printable characters."
        )


def check_std(
    model: CalibrationModel, i: int, sd: float, status: str, where: str
) -> None:
    """A parameter's std (file units): >= 0, and given only for an estimated parameter
    (a large one is kinecal's own: a marker seen in one pose, 9e6 mm)."""
    ps = model.layout.specs[i]
    unit = ps.unit.file_unit
    if sd < 0:
        raise ConfigError(
            f"{where}: expected a standard deviation >= 0 (or null); got {sd!r}."
        )
    if status != "estimated":
        raise ConfigError(
            f"{where}: {sd:g} {unit}, but status is {status!r} (the data did not "
            "determine it: no standard deviation); expected null, or status "
            "'estimated'."
        )
