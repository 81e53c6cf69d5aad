"""Sub-pixel laser-stripe centres of grey images: one centre per stripe cross-section.

Two methods:

- ``"ridge"`` (default): a Hessian ridge detector after Steger (1998) for stripes of any
  direction, straight or curved (:mod:`kinecal.sensor._ridge` describes it: scale
  matched to the stripe, sub-pixel position along the normal, linking into curves, the
  primary stripe chosen against reflections, background removal, saturation flagged
  and fitted on the flanks).
- ``"rows"``: the first extractor, kept for comparisons: one centre per image row, for
  stripes that run along the columns (the rotary sensor's mirror axis is parallel to the
  camera's y axis). Per row: the image is smoothed along the row (box of ``smooth``
  pixels) against speckle and its maximum found; rows whose peak does not stand out
  from the background (a global robust level and noise) by ``snr`` noise levels, or by
  ``min_rel`` of the brightest stripe, are dropped; the centre is the intensity-weighted
  centroid of the raw pixels within ``+-half_window`` of the peak above ``threshold``
  x peak over the background, and rows whose profile is too wide (``max_width`` px RMS)
  are dropped. Horizontal stripes, gradients of the background and saturation defeat it.

Both return an array (K, 7) of columns :data:`STRIPE_COLUMNS`: ``u_px, v_px`` (pixel
-centre convention: the centre of pixel (row v, column u) is (u, v), so pixel (0, 0)
spans -0.5..0.5), the unit normal ``nx, ny`` across the stripe, its ``width_px`` (FWHM),
its ``peak`` over the background [grey levels] and ``flags`` (bits :data:`SATURATED`,
:data:`FIT_FAILED`, :data:`BORDER`, :data:`NEIGHBOUR`; see :mod:`kinecal.sensor._ridge`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from kinecal._parallel import thread_map
from kinecal.errors import ConfigError, DataError
from kinecal.sensor._cv import require_cv2
from kinecal.sensor._ridge import (
    BORDER,
    FIT_FAILED,
    NEIGHBOUR,
    SATURATED,
    RidgeOptions,
    ridge_centres,
)
from kinecal.typing import Float

__all__ = [
    "BORDER",
    "FIT_FAILED",
    "NEIGHBOUR",
    "SATURATED",
    "STRIPE_COLUMNS",
    "extract_stripes",
    "extract_stripes_all",
]

STRIPE_COLUMNS = ("u_px", "v_px", "nx", "ny", "width_px", "peak", "flags")
_ROWS_OPTIONS = ("smooth", "half_window", "snr", "min_rel", "max_width", "threshold")
_RIDGE_OPTIONS = (
    "sigma_px",
    "low",
    "high",
    "min_length",
    "max_width_px",
    "saturation",
)


def extract_stripes_all(
    images: Sequence[np.ndarray | None], *, jobs: int = 0, **options: Any
) -> list[Float | None]:
    """:func:`extract_stripes` of every image (None stays None), on ``jobs`` threads.

    ``jobs=0`` uses one thread per CPU. Image decoding (OpenCV) and the array operations
    release the interpreter, so threads overlap. Items are taken from ``images`` inside
    the threads, so a sequence that reads a file on access is decoded in parallel too,
    with only ``jobs`` images in memory at a time. The result is the same for any
    ``jobs``.
    """
    _check_options(options)

    def one(i: int) -> Float | None:
        img = images[i]
        return None if img is None else extract_stripes(img, **options)

    return thread_map(one, range(len(images)), jobs)


def extract_stripes(
    image: np.ndarray, *, method: str = "ridge", **options: Any
) -> Float:
    """Stripe centres of one grey image (H, W): array (K, 7), see :data:`STRIPE_COLUMNS`.

    ``method``: ``"ridge"`` (any direction; options ``sigma_px``, ``low``, ``high``,
    ``min_length``, ``max_width_px``, ``saturation`` of
    :class:`~kinecal.sensor._ridge.RidgeOptions`) or ``"rows"`` (one centre per row,
    near-vertical stripes only; options ``smooth``, ``half_window``, ``snr``,
    ``min_rel``, ``max_width``, ``threshold``).
    """
    _check_options({"method": method, **options})
    img = _grey(image)
    if method == "rows":
        return _rows(img, **options)
    return ridge_centres(img, RidgeOptions(**options))


def _check_options(options: dict[str, Any]) -> None:
    method = options.get("method", "ridge")
    if method not in ("ridge", "rows"):
        raise ConfigError(f"stripe method must be 'ridge' or 'rows', got {method!r}")
    known = _RIDGE_OPTIONS if method == "ridge" else _ROWS_OPTIONS
    bad = sorted(set(options) - set(known) - {"method"})
    if bad:
        raise ConfigError(
            f"unknown option(s) {', '.join(bad)} of stripe method {method!r}; "
            f"expected {', '.join(known)}"
        )


def _grey(image: np.ndarray) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        raise DataError(
            "extract_stripes: expected a grey image (H, W), got a colour image"
        )
    if img.ndim != 2 or min(img.shape) < 3:
        raise DataError(
            f"extract_stripes: expected a grey image (H, W), got shape {img.shape}"
        )
    if img.dtype == np.bool_ or not np.issubdtype(img.dtype, np.number):
        raise DataError(f"extract_stripes: expected grey levels, got {img.dtype}")
    if img.dtype not in (np.uint8, np.uint16, np.float32):
        img = img.astype(np.float32)
    return img


def _rows(
    img: np.ndarray,
    *,
    smooth: int = 5,
    half_window: int = 7,
    snr: float = 8.0,
    min_rel: float = 0.08,
    max_width: float = 6.0,
    threshold: float = 0.2,
) -> Float:
    """The per-row centroid (the module docstring); (K, 7) with ``nx, ny = 1, 0``."""
    cv2 = require_cv2("stripe extraction")
    f = img.astype(np.float32, copy=False)
    H, W = f.shape
    # Background level and noise from a sparse sample of the image.
    sample = f[::7, ::13].ravel()
    bg = float(np.median(sample))
    noise = 1.4826 * float(np.median(np.abs(sample - bg))) or 0.5
    k = max(int(smooth), 1)
    sm = cv2.blur(f, (k, 1), borderType=cv2.BORDER_REPLICATE) if k > 1 else f
    col = np.argmax(sm, axis=1)
    rows = np.arange(H)
    peak = sm[rows, col] - bg
    if peak.max(initial=0.0) <= 0:
        return np.zeros((0, 7))
    keep = (peak > snr * noise / np.sqrt(k)) & (peak >= min_rel * peak.max())
    r, c, pk = rows[keep], col[keep], peak[keep]
    if r.size == 0:
        return np.zeros((0, 7))
    # Windows of raw pixels around each peak (clipped at the image border).
    offs = np.arange(-half_window, half_window + 1)
    cols = np.clip(c[:, None] + offs[None, :], 0, W - 1)
    win = f[r[:, None], cols] - bg
    w = np.clip(win - threshold * pk[:, None], 0.0, None)
    inside = (c[:, None] + offs[None, :] >= 0) & (c[:, None] + offs[None, :] < W)
    w = w * inside
    sw = w.sum(axis=1)
    good = sw > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        u = c + (w * offs).sum(axis=1) / sw
        spread = np.sqrt(
            np.clip((w * offs**2).sum(axis=1) / sw - (u - c) ** 2, 0.0, None)
        )
    good &= spread <= max_width
    n = int(good.sum())
    out = np.zeros((n, 7))
    out[:, 0] = u[good]
    out[:, 1] = r[good]
    out[:, 2] = 1.0
    out[:, 4] = 2.0 * np.sqrt(2.0 * np.log(2.0)) * spread[good]
    out[:, 5] = pk[good]
    return out
