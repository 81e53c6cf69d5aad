"""The sensor as a whole: camera + light planes, reconstruction of scans."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from kinecal.errors import ConfigError, DataError
from kinecal.sensor._camera import Camera, paper_camera
from kinecal.sensor._planes import LightPlanes, intersect_planes, rotary_planes
from kinecal.sensor._stripes import FIT_FAILED, extract_stripes_all
from kinecal.typing import Float

__all__ = ["ScanCloud", "Sensor", "paper_sensor"]


@dataclass(frozen=True)
class ScanCloud:
    """Points of one scan [m] in the camera frame, with their pixel and light plane."""

    points: Float  # (K, 3)
    uv: Float  # (K, 2)
    plane: np.ndarray  # (K,) light-plane index


@dataclass(frozen=True)
class Sensor:
    """A calibrated rotary laser sensor."""

    camera: Camera
    planes: LightPlanes

    def reconstruct(self, uv: Float, plane: np.ndarray) -> Float:
        """3-D points (K, 3) [m] of stripe pixels ``uv`` (K, 2) lit by planes ``plane``.

        Undistortion (Eq. 2) then the ray-plane intersection (Eq. 4-5), all at once.
        """
        plane = np.asarray(plane, np.intp)
        if plane.size and (plane.min() < 0 or plane.max() >= len(self.planes)):
            raise DataError(
                f"light-plane index out of range 0..{len(self.planes) - 1}: "
                f"{int(plane.min())}..{int(plane.max())}"
            )
        return intersect_planes(self.planes, self.camera.rays(uv), plane)

    def scan(
        self,
        images: Sequence[np.ndarray],
        plane: np.ndarray | None = None,
        *,
        jobs: int = 0,
        **extract_options: Any,
    ) -> ScanCloud:
        """Point cloud of one scan: image ``k`` was taken with light plane ``plane[k]``.

        The stripes are extracted on ``jobs`` threads (0: one per CPU; see
        :func:`~kinecal.sensor.extract_stripes_all`, which also takes a sequence that
        reads its images on access) with ``extract_options`` (``method`` and its
        options, see :func:`~kinecal.sensor.extract_stripes`). Every centre becomes a
        point, except those whose saturated profile could not be fitted (flag
        ``FIT_FAILED``: their position is not known to the stripe's precision).
        """
        n = len(images)
        idx = np.arange(n) if plane is None else np.asarray(plane, np.intp)
        if idx.shape != (n,):
            raise DataError(f"scan: {n} images but {idx.size} plane indices")
        stripes = extract_stripes_all(images, jobs=jobs, **extract_options)
        found = [f for f in stripes if f is not None]
        if len(found) != n:
            raise DataError(f"scan: {n - len(found)} of the {n} images are missing")
        found = [f[(f[:, 6].astype(np.int64) & FIT_FAILED) == 0] for f in found]
        uv = np.concatenate([f[:, :2] for f in found]) if found else np.zeros((0, 2))
        pl = (
            np.concatenate([np.full(f.shape[0], i) for f, i in zip(found, idx)])
            if found
            else np.zeros(0, np.intp)
        )
        pts = self.reconstruct(uv, pl)
        ok = np.all(np.isfinite(pts), axis=1)
        return ScanCloud(pts[ok], uv[ok], pl[ok].astype(np.intp))

    def to_dict(self) -> dict[str, Any]:
        return {"camera": self.camera.to_dict(), "light_planes": self.planes.to_dict()}

    @classmethod
    def from_dict(cls, d: dict[str, Any], where: str = "sensor") -> Sensor:
        if not isinstance(d, dict) or "camera" not in d or "light_planes" not in d:
            raise ConfigError(f"{where}: expected keys 'camera' and 'light_planes'")
        return cls(
            Camera.from_dict(d["camera"], f"{where}: camera"),
            LightPlanes.from_dict(d["light_planes"], f"{where}: light_planes"),
        )


def paper_sensor() -> Sensor:
    """The paper's sensor: its camera, 120 planes over 20 deg, baseline 69 mm (Sec. 5.1)."""
    return Sensor(paper_camera(), rotary_planes())
