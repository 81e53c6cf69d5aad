"""Argument helpers shared by the ``kinecal sensor`` command modules."""

from __future__ import annotations

from typing import Any

import click


def _board(text: str, square_mm: float) -> Any:
    """``--board COLSxROWS`` and ``--square-mm`` as a chessboard target."""
    from kinecal.workflows._sensor import chessboard_target

    try:
        return chessboard_target(text, square_mm)
    except ValueError as exc:  # (what is expected, the option)
        raise click.BadParameter(exc.args[0], param_hint=exc.args[1]) from None
