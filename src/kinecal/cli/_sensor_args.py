"""Argument helpers shared by the ``kinecal sensor`` command modules."""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

if TYPE_CHECKING:
    import numpy as np


def _board(text: str, square_mm: float) -> Any:
    from kinecal.sensor import ChessboardTarget

    m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if not m:
        raise click.BadParameter(
            f"expected COLSxROWS, e.g. 10x7; got {text!r}", param_hint="--board"
        )
    if square_mm <= 0:
        raise click.BadParameter("must be positive", param_hint="--square-mm")
    return ChessboardTarget(int(m.group(1)), int(m.group(2)), square_mm * 1e-3)


def _plane_index(path: Path) -> int:
    m = re.search(r"(\d+)\D*$", path.stem)
    if not m:
        from kinecal.errors import DataError

        raise DataError(
            f"{path}: stripe images must end with their light-plane number, e.g. plane_007.png"
        )
    return int(m.group(1))


def _triple(text: str, name: str) -> tuple[float, float, float]:
    try:
        vals = tuple(float(t) for t in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3:
        raise click.BadParameter(f"expected X,Y,Z; got {text!r}", param_hint=name)
    return vals


class _LazyImages(Sequence):
    """Image files read on access (``None`` entries stay ``None``)."""

    def __init__(self, paths: list[Path | None], reader: Callable[[Path], np.ndarray]):
        self._paths, self._read = paths, reader

    def __len__(self) -> int:
        return len(self._paths)

    def __getitem__(self, i):
        p = self._paths[i]
        return None if p is None else self._read(p)
