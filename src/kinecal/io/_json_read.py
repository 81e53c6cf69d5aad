"""JSON that kinecal reads back (report.json, manifest.json, PLAN.report.json): a file
nested too deeply for the decoder is a damaged file, not a defect.

``json.loads`` of ``[[[[...]]]]`` 100 000 deep raises ``RecursionError``, which no
reader caught: ``plan --add`` beside such a report.json, ``report`` and ``evaluate``
ended in an internal error. :func:`loads` raises :class:`json.JSONDecodeError` (a
``ValueError``, which every reader handles) instead. Standard library only.
"""

from __future__ import annotations

import json
from typing import Any

__all__ = ["loads"]


def loads(text: str) -> Any:
    """``json.loads(text)``; too deep a nesting raises :class:`json.JSONDecodeError`."""
    try:
        return json.loads(text)
    except RecursionError:
        raise json.JSONDecodeError(
            "nested too deeply (a damaged file?); expected kinecal's JSON", text, 0
        ) from None
