"""Argument helpers shared by the ``kinecal sensor`` command modules."""

from __future__ import annotations

import math
import re
from typing import Any

import click


def _board(text: str, square_mm: float) -> Any:
    from kinecal.sensor import ChessboardTarget

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise click.BadParameter(
            f"expected COLSxROWS, e.g. 10x7; got {text!r}", param_hint="--board"
        )
    cols, rows = int(m.group(1)), int(m.group(2))
    if min(cols, rows) < 3:
        raise click.BadParameter(
            f"expected at least 3 inner corners each way; got {text!r}",
            param_hint="--board",
        )
    if cols % 2 == rows % 2:
        raise click.BadParameter(
            f"expected one even and one odd count of inner corners (a board with two "
            f"even or two odd counts looks the same turned by 180 deg); got {text!r}",
            param_hint="--board",
        )
    if not (square_mm > 0 and math.isfinite(square_mm)):
        raise click.BadParameter(
            f"expected a finite number > 0 [mm]; got {square_mm}",
            param_hint="--square-mm",
        )
    return ChessboardTarget(cols, rows, square_mm * 1e-3)
