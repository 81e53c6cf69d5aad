"""Light planes of the rotary laser sensor (Eq. 3-5).

A line laser hits a mirror that turns about an axis parallel to the camera's y axis, at
the baseline distance from the camera centre; every mirror step gives one light plane
``n·X + b = 0`` in the camera frame (Eq. 3; ``n`` unit length, ``b`` in metres). A stripe
pixel's ray meets its plane at ``X = t·(x, y, 1)`` with ``t = -b / (n·(x, y, 1))``: the
closed form of Eq. (4)-(5) once the pixel is undistorted to normalised coordinates.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import ConfigError, DataError
from kinecal.typing import Float

__all__ = [
    "LightPlanes",
    "axis_fit",
    "fit_plane",
    "intersect_planes",
    "rotary_planes",
]


@dataclass(frozen=True)
class LightPlanes:
    """``M`` planes: unit normals ``n`` (M, 3) and offsets ``b`` (M,) [m]; optional source.

    ``source`` (3,) is where the light comes from (a point on the mirror axis); the
    renderer uses it for shadows, reconstruction does not need it.
    """

    n: Float
    b: Float
    source: Float | None = None

    def __post_init__(self) -> None:
        n = np.asarray(self.n, float)
        b = np.asarray(self.b, float)
        if n.ndim != 2 or n.shape[1] != 3 or b.shape != (n.shape[0],):
            raise ConfigError(
                f"light planes: n must be (M, 3) and b (M,), got {n.shape}, {b.shape}"
            )
        if not (np.all(np.isfinite(n)) and np.all(np.isfinite(b))):
            raise ConfigError("light planes: normals and offsets must be finite")
        norm = np.linalg.norm(n, axis=1)
        if np.any(np.abs(norm - 1.0) > 1e-6):
            raise ConfigError("light planes: normals must have unit length")
        object.__setattr__(self, "n", n)
        object.__setattr__(self, "b", b)

    def __len__(self) -> int:
        return int(self.n.shape[0])

    def distance(self, X: Float, index: np.ndarray | int) -> Float:
        """Signed distance [m] of points ``X`` (..., 3) from plane(s) ``index``."""
        return np.einsum("...i,...i->...", X, self.n[index]) + self.b[index]

    def to_dict(self) -> dict[str, object]:
        """Normals and offsets in mm, as stored in a sensor file."""
        d: dict[str, object] = {
            "unit": "mm",
            "planes": [
                [*map(float, nn), float(bb * 1e3)] for nn, bb in zip(self.n, self.b)
            ],
        }
        if self.source is not None:
            d["source_mm"] = [float(v * 1e3) for v in self.source]
        return d

    @classmethod
    def from_dict(
        cls, d: dict[str, object], where: str = "light_planes"
    ) -> LightPlanes:
        rows = d.get("planes")
        if not isinstance(rows, list) or not rows:
            raise ConfigError(
                f"{where}: 'planes' must be a non-empty list of [nx, ny, nz, b_mm]"
            )
        unit = d.get("unit", "mm")
        if unit != "mm":
            raise ConfigError(f"{where}: unit: expected 'mm'; got {unit!r}")
        arr = np.full((len(rows), 4), np.nan)
        for i, row in enumerate(rows):  # a file's rows: which one is wrong
            try:
                arr[i] = [float(v) for v in row]
                ok = bool(np.isfinite(arr[i]).all())
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ConfigError(
                    f"{where}: planes[{i}]: expected four finite numbers "
                    f"[nx, ny, nz, b_mm]; got {row!r}"
                )
        n = arr[:, :3]
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        if (norm[:, 0] < 1e-9).any():
            i = int(np.argmax(norm[:, 0] < 1e-9))
            raise ConfigError(
                f"{where}: planes[{i}]: normal [nx, ny, nz] is zero; expected a "
                "non-zero normal"
            )
        b_mm = np.abs(arr[:, 3]) / norm[:, 0]
        if np.median(b_mm) < 1.0:
            raise ConfigError(
                f"{where}: planes: offsets b_mm {np.median(b_mm):.3g} mm from the "
                "camera (median); expected millimetres (a light plane through the "
                "camera centre cannot triangulate: metres given?)"
            )
        src = d.get("source_mm")
        return cls(
            n / norm,
            arr[:, 3] / norm[:, 0] * 1e-3,
            None if src is None else np.asarray(src, float) * 1e-3,
        )


def rotary_planes(
    n_planes: int = 120,
    sweep_deg: float = 20.0,
    baseline: float = 0.069,
    working_distance: float = 0.125,
    axis_tilt_deg: tuple[float, float] = (0.0, 0.0),
) -> LightPlanes:
    """The planes of a rotary line-laser sensor (Sec. 5.1: 120 planes over 20 deg, 69 mm).

    The mirror axis passes through ``(baseline, 0, 0)`` along the camera's y axis (tilted
    by ``axis_tilt_deg`` about x and z, to model assembly errors). The middle plane crosses
    the optical axis at ``working_distance``; the planes sweep ``sweep_deg`` in equal steps.
    """
    if n_planes < 1:
        raise ConfigError("rotary_planes: n_planes must be at least 1")
    S = np.array([baseline, 0.0, 0.0])
    tx, tz = np.radians(axis_tilt_deg)
    a = np.array([0.0, 1.0, 0.0])
    a = (
        np.array([[1, 0, 0], [0, np.cos(tx), -np.sin(tx)], [0, np.sin(tx), np.cos(tx)]])
        @ a
    )
    a = (
        np.array([[np.cos(tz), -np.sin(tz), 0], [np.sin(tz), np.cos(tz), 0], [0, 0, 1]])
        @ a
    )
    phi_c = np.arctan2(baseline, working_distance)
    half = np.radians(sweep_deg) / 2.0
    phi = (
        phi_c + np.linspace(-half, half, n_planes)
        if n_planes > 1
        else np.array([phi_c])
    )
    d = np.stack([-np.sin(phi), np.zeros_like(phi), np.cos(phi)], axis=1)
    n = np.cross(a, d)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    b = -n @ S
    return LightPlanes(n, b, S)


def intersect_planes(planes: LightPlanes, rays: Float, index: np.ndarray) -> Float:
    """Points (N, 3) where rays (N, 3) (through the camera centre) meet planes ``index``.

    Eq. (5) in closed form. Rays (nearly) parallel to their plane give NaN rows.
    """
    n = planes.n[index]
    den = np.einsum("ij,ij->i", n, rays)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -planes.b[index] / den
    t[np.abs(den) < 1e-9] = np.nan
    return rays * t[:, None]


def fit_plane(points: Float) -> tuple[Float, float, float]:
    """Least-squares plane through points (N, 3): unit normal, offset ``b`` and RMS [m].

    The normal is oriented so that ``b`` is negative when the plane lies in front of the
    origin (as the light planes and targets seen by the camera do).
    """
    P = np.asarray(points, float)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] < 3:
        raise DataError(f"fit_plane: need at least 3 points (N, 3), got {P.shape}")
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c, full_matrices=False)
    if s[1] <= 1e-12 * max(s[0], 1e-300):
        raise DataError(
            "fit_plane: the points are collinear; a plane is not determined"
        )
    n = Vt[2]
    b = -float(n @ c)
    if b > 0:
        n, b = -n, -b
    rms = float(np.sqrt(np.mean(((P - c) @ n) ** 2)))
    return n, b, rms


def axis_fit(
    normals: Float, b: Float, clouds: list[Float], free: np.ndarray, all_planes: bool
) -> tuple[Float, Float, np.ndarray]:
    """Planes turning about one mirror axis, as the mechanism makes them.

    ``normals`` (M, 3), ``b`` (M,) [m]: the planes fitted on their own where ``free``;
    ``clouds[i]`` (K_i, 3) [m]: the points of plane ``i``. The axis is the line common to
    the free planes (direction: the null vector of their normals; point: least squares).
    A plane not free, or every plane when ``all_planes``, is then fitted with its normal
    perpendicular to the axis and the plane through it: one angle, in closed form.
    Planes without points get the angle of a linear fit of angle against plane index
    (the mirror steps evenly). Returns the normals, offsets and a status per plane
    ("free", "axis" or "unseen").
    """
    N = normals[free]
    _, _, Vt = np.linalg.svd(N)
    a = Vt[2]
    S = np.linalg.lstsq(N, -b[free], rcond=None)[0]
    S = S - a * (a @ S)
    e1 = np.cross(a, [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    psi = np.full(len(clouds), np.nan)
    status = np.where(free, "free", "unseen").astype(object)
    for i, c in enumerate(clouds):
        if c.shape[0] >= 2 and (all_planes or not free[i]):
            q = np.column_stack([(c - S) @ e1, (c - S) @ e2])
            _, V = np.linalg.eigh(q.T @ q)
            v = V[:, 0]
            psi[i] = np.arctan2(v[1], v[0])
            status[i] = "axis"
        elif free[i]:
            psi[i] = np.arctan2(normals[i] @ e2, normals[i] @ e1)
    # One branch for the angles (normals' sign is arbitrary).
    ref = psi[np.isfinite(psi)][0]
    psi = ref + (psi - ref + np.pi / 2) % np.pi - np.pi / 2
    seen = np.isfinite(psi)
    if not seen.all():
        idx = np.arange(len(clouds))
        coef = np.polyfit(idx[seen], psi[seen], 1)
        psi[~seen] = np.polyval(coef, idx[~seen])
    new_n = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2
    new_b = -(new_n @ S)
    flip = new_n[:, 0] < 0
    new_n[flip] *= -1
    new_b[flip] *= -1
    keep = free & ~np.asarray(all_planes, bool)
    new_n[keep] = normals[keep]
    new_b[keep] = b[keep]
    return new_n, new_b, status.astype(str)
