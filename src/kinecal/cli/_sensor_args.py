"""Argument helpers shared by the ``kinecal sensor`` command modules."""

from __future__ import annotations

import math
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
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise click.BadParameter(
            f"expected X,Y,Z (3 finite numbers); got {text!r}", param_hint=name
        )
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


class SameSize:
    """A reader of images that refuses one whose size differs from ``expected`` (the
    sensor file's camera, ``(width, height)``) or, without it, from the first image
    read: a binned or cropped image would be mapped through the wrong pixels (a 2x2
    binned scan with a full-size sensor file fitted a 15 mm sphere as 18 mm)."""

    def __init__(
        self,
        reader: Callable[[Path], np.ndarray],
        expected: tuple[int, int] | None = None,
        source: str = "",
    ) -> None:
        import threading

        self._read, self._size, self._source = reader, expected, source
        self._first: Path | None = None
        self._lock = threading.Lock()

    def __call__(self, path: Path) -> np.ndarray:
        from kinecal.errors import DataError

        img = self._read(path)
        size = (int(img.shape[1]), int(img.shape[0]))
        with self._lock:
            if self._size is None:
                self._size, self._first = size, path
        if size != self._size:
            w, h = self._size
            what = (
                f"the first image read, {self._first}"
                if self._first is not None
                else f"the camera of {self._source}"
            )
            raise DataError(
                f"{path}: {size[0]}x{size[1]} pixels; expected {w}x{h}, the size of "
                f"{what} (binned, cropped or another camera's images need a sensor "
                "file calibrated at their size)."
            )
        return img
