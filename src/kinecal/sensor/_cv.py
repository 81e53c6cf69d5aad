"""OpenCV, imported when first needed (it is the ``sensor`` extra)."""

from __future__ import annotations

from typing import Any

from kinecal.errors import DataError


def require_cv2(purpose: str) -> Any:
    """The ``cv2`` module, or a clear error naming what needs it and how to install it."""
    try:
        import cv2
    except ImportError:  # pragma: no cover - installed by make
        raise DataError(
            f"{purpose} needs OpenCV: pip install 'opencv-python-headless>=4.7,<5'"
        ) from None
    return cv2
