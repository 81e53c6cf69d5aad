"""Pinhole camera with Brown-Conrady distortion (Eq. 1-2, OpenCV's convention).

Pixel coordinates follow OpenCV: ``u`` along image columns, ``v`` along rows, and the
centre of pixel (0, 0) at (0, 0) (the pixel spans -0.5..0.5). Distortion acts on the
normalised coordinates ``x = X/Z, y = Y/Z``::

    r2 = x² + y²
    x_d = x (1 + k1 r2 + k2 r2² + k3 r2³) + 2 p1 x y + p2 (r2 + 2 x²)
    y_d = y (1 + k1 r2 + k2 r2² + k3 r2³) + p1 (r2 + 2 y²) + 2 p2 x y
    u = fx x_d + u0,  v = fy y_d + v0

Eq. (2) of the paper prints the same model in a compressed form; the coefficients it
reports (Sec. 5.1) are OpenCV's, so this is the model they belong to.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from kinecal.errors import ConfigError
from kinecal.typing import Float

__all__ = ["INTRINSICS", "Camera", "paper_camera"]

# Order of the intrinsic parameters in vectors and Jacobians.
INTRINSICS = ("fx", "fy", "u0", "v0", "k1", "k2", "k3", "p1", "p2")


@dataclass(frozen=True)
class Camera:
    """Intrinsics [px] and distortion (dimensionless) of one camera."""

    fx: float
    fy: float
    u0: float
    v0: float
    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0
    width: int = 1280
    height: int = 1024

    def __post_init__(self) -> None:
        names = ("fx", "fy", "u0", "v0", "k1", "k2", "k3", "p1", "p2")
        bad = [k for k in names if not np.isfinite(getattr(self, k))]
        if bad:
            raise ConfigError(
                f"camera parameter {bad[0]}: expected a finite number; got "
                f"{getattr(self, bad[0])}"
            )
        if self.fx <= 0 or self.fy <= 0:
            raise ConfigError(
                f"camera focal lengths must be positive, got {self.fx}, {self.fy}"
            )
        if self.width <= 0 or self.height <= 0:
            raise ConfigError(
                f"camera size must be positive, got {self.width}x{self.height}"
            )

    # -- OpenCV interop ------------------------------------------------------------------
    @property
    def K(self) -> Float:
        """The 3x3 camera matrix."""
        return np.array(
            [[self.fx, 0.0, self.u0], [0.0, self.fy, self.v0], [0.0, 0.0, 1.0]]
        )

    @property
    def dist(self) -> Float:
        """Distortion in OpenCV's order ``(k1, k2, p1, p2, k3)``."""
        return np.array([self.k1, self.k2, self.p1, self.p2, self.k3])

    @classmethod
    def from_opencv(cls, K: Float, dist: Float, size: tuple[int, int]) -> Camera:
        """From OpenCV's camera matrix, distortion vector and ``(width, height)``."""
        d = np.zeros(5)
        dd = np.asarray(dist, float).ravel()[:5]
        d[: dd.size] = dd
        return cls(
            fx=float(K[0, 0]),
            fy=float(K[1, 1]),
            u0=float(K[0, 2]),
            v0=float(K[1, 2]),
            k1=float(d[0]),
            k2=float(d[1]),
            p1=float(d[2]),
            p2=float(d[3]),
            k3=float(d[4]),
            width=int(size[0]),
            height=int(size[1]),
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            k: (int(v) if k in ("width", "height") else float(v))
            for k, v in asdict(self).items()
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], where: str = "camera") -> Camera:
        known = set(cls.__dataclass_fields__)
        unknown = set(d) - known
        if unknown:
            raise ConfigError(
                f"{where}: unknown key(s) {sorted(unknown)}; expected {sorted(known)}"
            )
        missing = {"fx", "fy", "u0", "v0", "width", "height"} - set(d)
        if missing:
            raise ConfigError(f"{where}: missing key(s) {sorted(missing)}")
        kw: dict[str, Any] = {}
        for k, v in d.items():
            size = k in ("width", "height")
            try:
                x = float(v)
                ok = math.isfinite(x) and (not size or x == int(x))
            except (TypeError, ValueError):
                ok = False
            if not ok:
                what = "a whole number of pixels" if size else "a finite number"
                raise ConfigError(
                    f"{where}: camera parameter {k}: expected {what}; got {v!r}"
                )
            kw[k] = int(x) if size else x
        w, h = kw.get("width", cls.width), kw.get("height", cls.height)
        for k, lim in (("u0", w), ("v0", h)):
            if w > 0 and h > 0 and not 0 <= kw[k] <= lim:
                raise ConfigError(
                    f"{where}: {k}: expected the principal point in the image, "
                    f"0..{lim} px; got {kw[k]:g}"
                )
        for k in ("fx", "fy"):
            if 0 < kw[k] < 0.05 * max(w, h):
                raise ConfigError(
                    f"{where}: {k}: expected the focal length in pixels (at least "
                    f"{0.05 * max(w, h):g} for a {w}x{h} image); got {kw[k]:g} "
                    "(millimetres?)"
                )
        try:
            return cls(**kw)
        except ConfigError as exc:  # the file's name in front of the check's message
            raise ConfigError(f"{where}: {exc}") from None

    def with_(self, **changes: float) -> Camera:
        return replace(self, **changes)  # type: ignore[arg-type]

    # -- distortion --------------------------------------------------------------------
    def distort(self, xy: Float) -> Float:
        """Normalised undistorted (..., 2) -> normalised distorted coordinates."""
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        xd = x * radial + 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x)
        yd = y * radial + self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def undistort(self, xy_d: Float, iterations: int = 20, tol: float = 1e-14) -> Float:
        """Invert :meth:`distort` by Newton's method (vectorised; exact to ~1e-15)."""
        xy = np.array(xy_d, dtype=float, copy=True)
        k1, k2, k3, p1, p2 = self.k1, self.k2, self.k3, self.p1, self.p2
        for _ in range(iterations):
            x, y = xy[..., 0], xy[..., 1]
            r2 = x * x + y * y
            radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d radial / d r2
            f = self.distort(xy) - xy_d
            # Jacobian [[a, b], [b, d]]: d x_d / d y equals d y_d / d x.
            a = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
            b = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
            d = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
            det = a * d - b * b
            dx = (d * f[..., 0] - b * f[..., 1]) / det
            dy = (-b * f[..., 0] + a * f[..., 1]) / det
            xy[..., 0] -= dx
            xy[..., 1] -= dy
            if np.max(np.abs(dx) + np.abs(dy), initial=0.0) < tol:
                break
        return xy

    # -- parameter vector and Jacobians -------------------------------------------------
    def intrinsics(self) -> Float:
        """The parameters (9,) in the order of :data:`INTRINSICS`."""
        return np.array([getattr(self, k) for k in INTRINSICS])

    def with_intrinsics(self, values: Float) -> Camera:
        """The same camera with the parameters (9,) of :data:`INTRINSICS` replaced."""
        changes = {k: float(v) for k, v in zip(INTRINSICS, values)}
        return replace(self, **changes)  # type: ignore[arg-type]

    def _distort_jacobian(self, xy: Float) -> tuple[Float, Float, Float]:
        """Distorted coordinates (..., 2), their Jacobian (..., 2, 2) w.r.t. ``xy`` and
        (..., 2, 5) w.r.t. ``(k1, k2, k3, p1, p2)``."""
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3))
        drad = self.k1 + r2 * (2.0 * self.k2 + 3.0 * self.k3 * r2)  # d radial / d r2
        p1, p2 = self.p1, self.p2
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)  # Eq. (2)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y  # Eq. (2)
        J_xy = np.empty((*x.shape, 2, 2))
        J_xy[..., 0, 0] = radial + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
        J_xy[..., 0, 1] = J_xy[..., 1, 0] = (
            2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
        )
        J_xy[..., 1, 1] = radial + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
        J_k = np.empty((*x.shape, 2, 5))
        r4 = r2 * r2
        J_k[..., 0, :] = np.stack(
            [x * r2, x * r4, x * r4 * r2, 2.0 * x * y, r2 + 2.0 * x * x], -1
        )
        J_k[..., 1, :] = np.stack(
            [y * r2, y * r4, y * r4 * r2, r2 + 2.0 * y * y, 2.0 * x * y], -1
        )
        return np.stack([xd, yd], -1), J_xy, J_k

    def project_jacobian(self, P_cam: Float) -> tuple[Float, Float, Float]:
        """Pixels (..., 2) of points ``P_cam`` (..., 3) [m, camera frame] with their
        Jacobians (..., 2, 3) w.r.t. the point [px/m] and (..., 2, 9) w.r.t. the
        intrinsics in the order of :data:`INTRINSICS` (Eq. 1-2)."""
        P = np.asarray(P_cam, float)
        iz = 1.0 / P[..., 2]
        xy = P[..., :2] * iz[..., None]
        xd, J_xd_xy, J_xd_k = self._distort_jacobian(xy)
        f = np.array([self.fx, self.fy])
        uv = xd * f + np.array([self.u0, self.v0])  # Eq. (1)
        J_xy_P = np.zeros((*P.shape[:-1], 2, 3))
        J_xy_P[..., 0, 0] = J_xy_P[..., 1, 1] = iz
        J_xy_P[..., :, 2] = -xy * iz[..., None]
        J_uv_P = f[:, None] * (J_xd_xy @ J_xy_P)
        J_uv_c = np.zeros((*P.shape[:-1], 2, 9))
        J_uv_c[..., 0, 0] = xd[..., 0]
        J_uv_c[..., 1, 1] = xd[..., 1]
        J_uv_c[..., 0, 2] = 1.0
        J_uv_c[..., 1, 3] = 1.0
        J_uv_c[..., 4:] = f[:, None] * J_xd_k
        return uv, J_uv_P, J_uv_c

    def normalised_jacobian(self, uv: Float) -> tuple[Float, Float, Float]:
        """Undistorted normalised coordinates (..., 2) of pixels ``uv`` (..., 2) with
        their Jacobians (..., 2, 9) w.r.t. the intrinsics (:data:`INTRINSICS`) and
        (..., 2, 2) w.r.t. the pixel: implicit differentiation of ``distort(xy) = ((u -
        u0) / fx, (v - v0) / fy)``."""
        uv = np.asarray(uv, float)
        xy = self.normalised(uv)
        xd, J_xd_xy, J_xd_k = self._distort_jacobian(xy)
        a, b, d = J_xd_xy[..., 0, 0], J_xd_xy[..., 0, 1], J_xd_xy[..., 1, 1]
        det = a * d - b * b  # the Jacobian is symmetric
        inv = np.stack([np.stack([d, -b], -1), np.stack([-b, a], -1)], -2)
        inv /= det[..., None, None]
        rhs = np.zeros((*uv.shape[:-1], 2, 9))
        rhs[..., 0, 0] = -xd[..., 0] / self.fx
        rhs[..., 1, 1] = -xd[..., 1] / self.fy
        rhs[..., 0, 2] = -1.0 / self.fx
        rhs[..., 1, 3] = -1.0 / self.fy
        rhs[..., 4:] = -J_xd_k
        J_xy_uv = inv * np.array([1.0 / self.fx, 1.0 / self.fy])
        return xy, inv @ rhs, J_xy_uv

    # -- projection --------------------------------------------------------------------
    def project(self, P_cam: Float) -> Float:
        """Points (..., 3) in the camera frame -> pixels (..., 2) (Eq. 1-2)."""
        P = np.asarray(P_cam, float)
        xy = P[..., :2] / P[..., 2:3]
        xd = self.distort(xy)
        return np.stack(
            [self.fx * xd[..., 0] + self.u0, self.fy * xd[..., 1] + self.v0], -1
        )

    def normalised(self, uv: Float) -> Float:
        """Pixels (..., 2) -> undistorted normalised coordinates (..., 2)."""
        uv = np.asarray(uv, float)
        xd = np.stack(
            [(uv[..., 0] - self.u0) / self.fx, (uv[..., 1] - self.v0) / self.fy], -1
        )
        return self.undistort(xd)

    def rays(self, uv: Float) -> Float:
        """Pixels (..., 2) -> ray directions (..., 3) with z = 1 (not unit length)."""
        xy = self.normalised(uv)
        return np.concatenate([xy, np.ones_like(xy[..., :1])], axis=-1)


def paper_camera() -> Camera:
    """The paper's camera (Sec. 5.1): MV-CA013-20GM, 16 mm lens, 1280 x 1024."""
    return Camera(
        fx=3423.018,
        fy=3420.949,
        u0=605.260,
        v0=580.506,
        k1=-0.163,
        k2=0.951,
        k3=-0.874,
        p1=0.000107,
        p2=-0.00119,
        width=1280,
        height=1024,
    )
