"""Sub-pixel stripe-centre extraction, one centre per image row.

The stripes of the rotary sensor run along the image columns (the mirror axis is parallel
to the camera's y axis), so every row crosses a stripe at most once. Per row:

1. the image is smoothed along the row (box of ``smooth`` pixels) against speckle and
   the row's maximum is found (one vectorised ``argmax`` over all rows);
2. rows whose peak does not stand out from the background (a global robust estimate of
   level and noise) by ``snr`` noise levels, or by ``min_rel`` of the brightest stripe,
   are dropped;
3. the centre is the intensity-weighted centroid of the raw pixels within ``±half_window``
   of the peak, above ``threshold`` x peak over the background (unbiased for a symmetric
   profile; 0.2 keeps enough of the profile that the centre does not lock to pixels: under
   0.01 px on a clean 8-bit Gaussian stripe), and rows whose profile is too wide to be
   a laser stripe (``max_width`` pixels RMS: ambient reflections) are dropped.

Pixel-centre convention: the centre of pixel (row v, column u) is (u, v).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import uniform_filter1d

from kinecal._parallel import thread_map
from kinecal.errors import DataError
from kinecal.typing import Float

__all__ = ["extract_stripes", "extract_stripes_all"]


def extract_stripes_all(
    images: Sequence[np.ndarray | None], *, jobs: int = 0, **options: float
) -> list[Float | None]:
    """:func:`extract_stripes` of every image (None stays None), on ``jobs`` threads.

    ``jobs=0`` uses one thread per CPU. Image decoding (OpenCV) and the array operations
    release the interpreter, so threads overlap: a scan of 120 PNG files of 1280 x 1024,
    read and extracted, took 2.8-3.1 s on one thread and 1.4-1.6 s on two (2-core VM).
    Items are taken from ``images`` inside the threads, so a sequence that reads a file on
    access is decoded in parallel too, with only ``jobs`` images in memory at a time. The
    result is the same for any ``jobs``.
    """

    def one(i: int) -> Float | None:
        img = images[i]
        return None if img is None else extract_stripes(img, **options)  # type: ignore[arg-type]

    return thread_map(one, range(len(images)), jobs)


def extract_stripes(
    image: np.ndarray,
    *,
    smooth: int = 5,
    half_window: int = 7,
    snr: float = 8.0,
    min_rel: float = 0.08,
    max_width: float = 6.0,
    threshold: float = 0.2,
) -> Float:
    """Stripe centres of one grey image (H, W): array (K, 3) of ``u, v, peak``.

    ``peak`` is the smoothed peak height above background, in the image's grey levels.
    """
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        raise DataError(
            "extract_stripes: expected a grey image (H, W), got a colour image"
        )
    if img.ndim != 2 or min(img.shape) < 3:
        raise DataError(
            f"extract_stripes: expected a grey image (H, W), got shape {img.shape}"
        )
    f = img.astype(np.float32, copy=False)
    H, W = f.shape
    # Background level and noise from a sparse sample of the image.
    sample = f[::7, ::13].ravel()
    bg = float(np.median(sample))
    noise = 1.4826 * float(np.median(np.abs(sample - bg))) or 0.5
    sm = uniform_filter1d(f, size=max(int(smooth), 1), axis=1, mode="nearest")
    col = np.argmax(sm, axis=1)
    rows = np.arange(H)
    peak = sm[rows, col] - bg
    if peak.max(initial=0.0) <= 0:
        return np.zeros((0, 3))
    keep = (peak > snr * noise / np.sqrt(max(smooth, 1))) & (
        peak >= min_rel * peak.max()
    )
    r = rows[keep]
    c = col[keep]
    pk = peak[keep]
    if r.size == 0:
        return np.zeros((0, 3))
    # Windows of raw pixels around each peak (clipped at the image border).
    offs = np.arange(-half_window, half_window + 1)
    cols = np.clip(c[:, None] + offs[None, :], 0, W - 1)
    win = f[r[:, None], cols] - bg
    thr = threshold * pk[:, None]
    w = np.clip(win - thr, 0.0, None)
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
    return np.stack([u[good], r[good].astype(float), pk[good]], axis=1)
