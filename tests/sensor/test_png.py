"""The scan's PNG decoder (kinecal.sensor.decode_grey_png) against OpenCV's."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest

from kinecal.sensor import decode_grey_png


def _png(img: np.ndarray, kinds: list[int], colour: int = 0) -> bytes:
    """A PNG of ``img`` whose rows are filtered by ``kinds`` in turn (0 None, 1 Sub,
    2 Up, 3 Average)."""
    H = img.shape[0]
    bpp = 2 if img.dtype == np.uint16 else 1
    data = img.astype(">u2").tobytes() if bpp == 2 else img.tobytes()
    rows = np.frombuffer(data, np.uint8).reshape(H, -1).astype(np.int64)
    out, prev = [], np.zeros(rows.shape[1], np.int64)
    for y in range(H):
        k, r = kinds[y % len(kinds)], rows[y]
        left = np.concatenate([np.zeros(bpp, np.int64), r[:-bpp]])
        f = {0: r, 1: r - left, 2: r - prev, 3: r - (left + prev) // 2}[k]
        out.append(bytes([k]) + (f % 256).astype(np.uint8).tobytes())
        prev = r

    def chunk(t: bytes, d: bytes) -> bytes:
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d))

    hdr = struct.pack(">IIBBBBB", img.shape[1], H, 8 * bpp, colour, 0, 0, 0)
    idat = zlib.compress(b"".join(out))
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", hdr)
        + chunk(b"IDAT", idat[:100])
        + chunk(b"IDAT", idat[100:])
        + chunk(b"IEND", b"")
    )


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("kinds", [[0], [1], [2], [0, 1, 1]])
def test_decodes_what_opencv_decodes(dtype, kinds):
    rng = np.random.default_rng(3)
    img = rng.integers(0, np.iinfo(dtype).max + 1, (37, 53)).astype(dtype)
    data = _png(img, kinds)
    ref = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    np.testing.assert_array_equal(ref, img)
    out = decode_grey_png(data)
    assert out is not None and out.dtype == dtype
    np.testing.assert_array_equal(out, img)


def test_opencvs_own_files_and_what_is_left_to_opencv():
    rng = np.random.default_rng(4)
    img = rng.integers(0, 256, (64, 80)).astype(np.uint8)
    _, buf = cv2.imencode(".png", img)  # the simulator's files: Sub-filtered rows
    np.testing.assert_array_equal(decode_grey_png(buf.tobytes()), img)
    assert decode_grey_png(_png(img, [1, 2])) is None  # Sub and Up mixed
    assert decode_grey_png(_png(img, [3])) is None  # Average
    rgb = np.repeat(img[:, :, None], 3, axis=2)
    _, buf = cv2.imencode(".png", rgb)
    assert decode_grey_png(buf.tobytes()) is None  # colour
    data = bytearray(_png(img, [1]))
    data[50] ^= 0xFF  # a broken IDAT: its CRC does not match
    assert decode_grey_png(bytes(data)) is None
    assert decode_grey_png(b"not a png") is None
    assert decode_grey_png(_png(img, [1])[:60]) is None  # truncated
