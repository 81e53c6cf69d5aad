"""Sensor files: grey images, point clouds, stripe centres and the sensor YAML."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from kinecal import _yaml as yaml
from kinecal.errors import ConfigError, DataError
from kinecal.io._files import atomic_write_bytes, atomic_write_text
from kinecal.io._table import read_table

if (
    TYPE_CHECKING
):  # the sensor package (and scipy.ndimage) loads when a sensor file does
    from kinecal.sensor import Camera, Sensor

__all__ = [
    "image_files",
    "load_sensor",
    "read_cloud",
    "read_image",
    "save_sensor",
    "write_cloud",
    "write_image",
    "write_stripes",
]

SENSOR_FORMAT = 1


def _cv2() -> Any:
    from kinecal.sensor._cv import require_cv2

    return require_cv2("reading and writing images")


def read_image(path: str | Path) -> np.ndarray:
    """A grey 8- or 16-bit image (H, W); colour images are refused with a clear error."""
    from kinecal._outputs import note_input

    note_input(path)
    p = Path(path)
    if not p.is_file():
        raise DataError(f"{p}: image not found.")
    cv2 = _cv2()
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DataError(
            f"{p}: not an image OpenCV can read (expected PNG, TIFF, BMP ...)."
        )
    if img.ndim == 3:
        if img.shape[2] == 1:
            img = img[:, :, 0]
        else:
            b, g, r = (img[:, :, k].astype(np.int64) for k in range(3))
            if not (np.array_equal(b, g) and np.array_equal(g, r)):
                raise DataError(
                    f"{p}: a colour image ({img.shape[2]} channels); expected 8- or 16-bit grey."
                )
            img = img[:, :, 0]
    if img.dtype not in (np.uint8, np.uint16):
        raise DataError(f"{p}: pixel type {img.dtype}; expected 8- or 16-bit grey.")
    if min(img.shape) < 3:
        raise DataError(
            f"{p}: {img.shape[1]}x{img.shape[0]} pixels; expected an image of at least "
            "3x3 pixels."
        )
    return img


def write_image(
    path: str | Path, img: np.ndarray, *, force: bool = False, sync: bool = True
) -> Path:
    """Write a grey image as PNG, atomically (a temporary file renamed into place).

    ``sync=False`` skips flushing the file to disk before the rename (10-30 ms per file
    here): for the many images of a simulated session, which a crash would simply have
    to render again; a reader still never sees a partial file.
    """
    cv2 = _cv2()
    ok, buf = cv2.imencode(".png", img)
    if not ok:  # pragma: no cover
        raise DataError(f"{path}: could not encode the image")
    return atomic_write_bytes(path, buf.tobytes(), force=force, sync=sync)


def image_files(folder: str | Path, pattern: str = "*.png") -> list[Path]:
    """Image files of a folder, sorted by name; an empty folder is an error."""
    d = Path(folder)
    if not d.is_dir():
        raise DataError(f"{d}: not a folder.")
    files = sorted(p for p in d.glob(pattern) if p.is_file())
    if not files:
        raise DataError(f"{d}: no images matching {pattern}.")
    from kinecal._outputs import note_input

    for f in files:  # the command's inputs: no output may replace one
        note_input(f)
    return files


def read_cloud(path: str | Path) -> np.ndarray:
    """Points (N, 3) [m] from a CSV with columns ``x_mm, y_mm, z_mm``."""
    from kinecal._outputs import note_input

    note_input(path)
    t = read_table(path)
    for c in ("x_mm", "y_mm", "z_mm"):
        if c not in t.header:
            raise DataError(f"{t.path}: missing column '{c}' (need x_mm, y_mm, z_mm).")
    if not t.rows:
        raise DataError(f"{t.path}: no points.")
    return np.column_stack([t.numbers(c) for c in ("x_mm", "y_mm", "z_mm")]) * 1e-3


def write_cloud(
    path: str | Path,
    points: np.ndarray,
    extra: dict[str, np.ndarray] | None = None,
    *,
    force: bool = False,
) -> Path:
    """Write points [m] as ``x_mm, y_mm, z_mm`` (+ extra columns), atomically."""
    cols = ["x_mm", "y_mm", "z_mm"]
    data = [points * 1e3]
    fmt = ["%.6f"] * 3
    for k, v in (extra or {}).items():
        cols.append(k)
        data.append(np.asarray(v, float).reshape(-1, 1))
        fmt.append(
            "%.4f" if not np.issubdtype(np.asarray(v).dtype, np.integer) else "%d"
        )
    return _write_rows(path, cols, np.hstack(data), fmt, force)


def write_stripes(
    path: str | Path, stripes: np.ndarray, *, force: bool = False
) -> Path:
    """Write stripe centres (K, 2..7) as CSV, ``u_px, v_px`` first, atomically.

    Columns, as many as ``stripes`` has: ``u_px, v_px, nx, ny, width_px, peak, flags``
    (see :data:`kinecal.sensor.STRIPE_COLUMNS`); 3 columns are the older ``u_px, v_px,
    peak``. Positions to 1e-4 px, ``flags`` as an integer.
    """
    data = np.asarray(stripes, float)
    if data.ndim != 2 or not 2 <= data.shape[1] <= 7:
        raise DataError(
            f"write_stripes: expected centres (K, 2..7), got shape {data.shape}"
        )
    if data.shape[1] == 3:
        cols = ["u_px", "v_px", "peak"]
    else:
        cols = ["u_px", "v_px", "nx", "ny", "width_px", "peak", "flags"][
            : data.shape[1]
        ]
    fmt = ["%.4f", "%.4f", "%.5f", "%.5f", "%.3f", "%.2f", "%d"][: len(cols)]
    if data.shape[1] == 3:
        fmt = ["%.4f", "%.4f", "%.2f"]
    return _write_rows(path, cols, data, fmt, force)


def _write_rows(
    path: str | Path, cols: list[str], data: np.ndarray, fmt: list[str], force: bool
) -> Path:
    return atomic_write_bytes(path, _csv_blocks(cols, data, fmt), force=force)


_BLOCK = 20_000  # rows formatted at a time


def _csv_blocks(cols: list[str], data: np.ndarray, fmt: list[str]) -> Iterator[bytes]:
    """The CSV text of ``data`` in pieces: the header, then blocks of rows, each by one
    %-format of the whole block (the text of :func:`numpy.savetxt` with ``fmt`` and
    ``,``; savetxt formats row by row in Python, 0.3 s for a scan's 38 000 points)."""
    yield (",".join(cols) + "\n").encode()
    line = ",".join(fmt) + "\n"
    for i in range(0, data.shape[0] if data.size else 0, _BLOCK):
        block = data[i : i + _BLOCK]
        yield ((line * block.shape[0]) % tuple(block.ravel().tolist())).encode()


def save_sensor(
    path: str | Path,
    sensor: Sensor | Camera,
    info: dict[str, Any] | None = None,
    *,
    force: bool = False,
) -> Path:
    """Write a sensor (camera + light planes) or a camera alone as YAML, atomically."""
    from kinecal.sensor import Camera

    doc: dict[str, Any] = {"format": SENSOR_FORMAT}
    if isinstance(sensor, Camera):
        doc["camera"] = sensor.to_dict()
    else:
        doc.update(sensor.to_dict())
    if info:
        doc["calibration"] = info
    return atomic_write_text(path, yaml.dump(doc, sort_keys=False), force=force)


def load_sensor(path: str | Path, *, need_planes: bool = True) -> Sensor | Camera:
    """Read a sensor YAML; a file with only a camera gives the :class:`Camera`."""
    from kinecal._outputs import note_input

    note_input(path)
    from kinecal.sensor import Camera, LightPlanes, Sensor

    p = Path(path)
    try:
        doc = yaml.load(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError(f"{p}: file not found.") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{p}: not a text file; expected a sensor YAML.") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: not valid YAML ({exc}).") from None
    if not isinstance(doc, dict) or "camera" not in doc:
        raise ConfigError(f"{p}: expected a sensor file with a 'camera' section.")
    fmt = doc.get("format", SENSOR_FORMAT)
    if type(fmt) is not int or fmt != SENSOR_FORMAT:  # true == 1 in Python
        raise ConfigError(
            f"{p}: format: expected {SENSOR_FORMAT} (the sensor files this kinecal "
            f"reads); got {fmt!r}"
        )
    if "light_planes" not in doc:
        if need_planes:
            raise ConfigError(
                f"{p}: no 'light_planes' section; calibrate the planes first "
                "(kinecal sensor calibrate-planes)."
            )
        return Camera.from_dict(doc["camera"], f"{p}: camera")
    return Sensor(
        Camera.from_dict(doc["camera"], f"{p}: camera"),
        LightPlanes.from_dict(doc["light_planes"], f"{p}: light_planes"),
    )
