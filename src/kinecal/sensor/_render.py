"""Image-level simulator of the rotary laser sensor: stripe images.

Scenes are spheres and planes in the camera frame (metres). A pixel sees the first
surface its ray hits; a light plane lights a surface point with a Gaussian sheet profile
across the plane (``laser_sigma``), Lambertian shading, shadows from the light source and
multiplicative speckle; the camera adds a dark level, read noise, saturation and
quantisation. Each pixel integrates over its area (``supersample`` x ``supersample``
sub-pixel rays), so the stripe centres carry no rendering bias beyond that of real optics.

Rendering a stripe only traces sub-pixel rays in the band of pixels near the lit curve.
The band is found from a per-scene index (:meth:`StripeRenderer.prepare`): when the
planes turn about one axis (a rotary sensor), every surface point lies on exactly one
plane of the pencil, at an angle ``psi`` about the axis; the pixels sorted by that angle
give each plane's candidates by a binary search, and the exact test runs on those only
(other plane sets fall back to a test of every pixel). The background's read noise is
drawn from a table. A 1280 x 1024 stripe image takes 15-20 ms.
:meth:`StripeRenderer.true_stripe` gives the exact centre per row (where the ray meets
the light plane on the surface), the ground truth for extraction, and the fast
point-level mode of the simulator.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from kinecal.errors import ConfigError
from kinecal.sensor._board import (
    ChessboardTarget,
    _normal_quantiles,
    gaussian_noise,
    pixel_normalised,
    render_chessboard,
)
from kinecal.sensor._camera import Camera
from kinecal.sensor._planes import LightPlanes
from kinecal.typing import Float

__all__ = [
    "ChessboardTarget",
    "PlaneSurface",
    "PreparedScene",
    "Scene",
    "SphereSurface",
    "StripeRenderer",
    "render_chessboard",
]

# Pixels whose band half-width about the axis exceeds this [rad] (object edges, points
# near the axis) are tested for every plane instead of through the sorted index.
_WIDE_RAD = 0.02


@dataclass(frozen=True)
class SphereSurface:
    center: Float
    radius: float
    albedo: float = 1.0


@dataclass(frozen=True)
class PlaneSurface:
    """An infinite plane through ``point`` with unit ``normal`` (a flat target)."""

    point: Float
    normal: Float
    albedo: float = 1.0


@dataclass(frozen=True)
class Scene:
    spheres: tuple[SphereSurface, ...] = ()
    planes: tuple[PlaneSurface, ...] = ()

    def cast(self, rays: Float) -> tuple[Float, Float, Float, np.ndarray]:
        """First hit of rays (N, 3) from the origin: depth ``t``, point, normal, object id.

        Object ids: spheres first (0..), then planes; -1 where nothing is hit.
        """
        N = rays.shape[0]
        t_best = np.full(N, np.inf)
        obj = np.full(N, -1, np.int32)
        normal = np.zeros((N, 3))
        rr = np.einsum("ij,ij->i", rays, rays)
        for k, s in enumerate(self.spheres):
            c = np.asarray(s.center, float)
            bc = rays @ c
            disc = bc * bc - rr * (c @ c - s.radius**2)
            ok = disc >= 0
            with np.errstate(invalid="ignore"):
                t = (bc - np.sqrt(np.where(ok, disc, 0.0))) / rr
            hit = ok & (t > 0) & (t < t_best)
            t_best[hit] = t[hit]
            obj[hit] = k
        for k, p in enumerate(self.planes):
            n = np.asarray(p.normal, float)
            den = rays @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (np.asarray(p.point, float) @ n) / den
            hit = (np.abs(den) > 1e-12) & (t > 0) & (t < t_best)
            t_best[hit] = t[hit]
            obj[hit] = len(self.spheres) + k
        X = rays * np.where(obj >= 0, t_best, np.nan)[:, None]
        for k, s in enumerate(self.spheres):
            m = obj == k
            normal[m] = (X[m] - s.center) / s.radius
        for k, p in enumerate(self.planes):
            m = obj == len(self.spheres) + k
            n = np.asarray(p.normal, float)
            # Face the camera.
            normal[m] = n if n[2] < 0 else -n
        return t_best, X, normal, obj

    def albedo(self, obj: np.ndarray) -> Float:
        alb = np.array(
            [s.albedo for s in self.spheres] + [p.albedo for p in self.planes] + [0.0]
        )
        return alb[obj]  # obj == -1 picks the trailing 0

    def shadowed(self, X: Float, source: Float, obj: np.ndarray) -> np.ndarray:
        """Points whose segment to the light ``source`` is blocked by another sphere."""
        out = np.zeros(X.shape[0], bool)
        d = source - X
        dd = np.einsum("ij,ij->i", d, d)
        for k, s in enumerate(self.spheres):
            oc = X - s.center
            b = np.einsum("ij,ij->i", oc, d)
            c = np.einsum("ij,ij->i", oc, oc) - s.radius**2
            disc = b * b - dd * c
            ok = (disc > 0) & (obj != k)
            sq = np.sqrt(np.where(ok, disc, 0.0))
            t1 = (-b - sq) / dd
            t2 = (-b + sq) / dd
            out |= ok & (((t1 > 1e-9) & (t1 < 1.0)) | ((t2 > 1e-9) & (t2 < 1.0)))
        return out


@dataclass(frozen=True)
class _Pencil:
    """Planes turning about one axis: a point ``S`` on it, unit ``e1, e2`` across it and
    every plane's angle ``psi`` (its normal is ``cos psi e1 + sin psi e2``)."""

    S: Float
    e1: Float
    e2: Float
    psi: Float
    centre: float


def _pencil(planes: LightPlanes) -> _Pencil | None:
    """The common axis of the planes, or None where they have none (to 1e-9 rad/m)."""
    S = planes.source
    if S is None or len(planes) < 2:
        return None
    _, sv, Vt = np.linalg.svd(planes.n)
    if (
        sv[2] > 1e-9 * sv[0]
        or np.max(np.abs(planes.distance(S, np.arange(len(planes))))) > 1e-9
    ):
        return None
    a = Vt[2]
    e1 = np.cross(a, [0.0, 0.0, 1.0] if abs(a[2]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    psi = np.arctan2(planes.n @ e2, planes.n @ e1)
    psi = psi[0] + (psi - psi[0] + np.pi / 2) % np.pi - np.pi / 2  # one branch
    return _Pencil(np.asarray(S, float), e1, e2, psi, float(np.mean(psi)))


@dataclass(frozen=True)
class PreparedScene:
    """What :meth:`StripeRenderer.render` needs of a scene, computed once (read-only,
    so threads can render one prepared scene at the same time).

    ``X32`` (H*W, 3) float32: first surface point of every pixel-centre ray [m] (NaN:
    none). With a pencil of planes: ``order`` the pixels sorted by their angle ``psi``
    about the axis, ``psi`` (sorted), ``half`` (H*W,) the angle within which a plane may
    light a pixel, ``reach`` its largest value over the sorted pixels and ``wide`` the
    pixels tested for every plane.
    """

    scene: Scene
    X32: np.ndarray
    order: np.ndarray | None = None
    psi: np.ndarray | None = None
    half: np.ndarray | None = None
    reach: float = 0.0
    wide: np.ndarray | None = None


@dataclass
class StripeRenderer:
    """Renders what the sensor's camera sees when light plane ``i`` is on."""

    camera: Camera
    planes: LightPlanes
    laser_sigma: float = 40e-6  # 1-sigma half-thickness of the light sheet [m]
    peak: float = 180.0  # grey level of a stripe on a white surface facing the light
    dark: float = 6.0  # dark level [grey levels]
    read_noise: float = 1.2  # [grey levels]
    speckle: float = 0.15  # contrast of multiplicative speckle (0: none)
    supersample: int = 3
    bit_depth: int = 8
    _prepared: PreparedScene | None = field(default=None, repr=False)
    _depth_data: tuple[Scene, tuple[Float, Float, Float, np.ndarray]] | None = field(
        default=None, repr=False
    )
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def __post_init__(self) -> None:
        if self.bit_depth not in (8, 16):
            raise ConfigError(f"bit_depth must be 8 or 16, got {self.bit_depth}")
        if self.planes.source is None:
            raise ConfigError("the renderer needs the light source of the planes")

    @property
    def pixel_rays(self) -> Float:
        """Rays (H*W, 3) through every pixel centre."""
        xy = pixel_normalised(self.camera)
        return np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)

    def _surface32(self, scene: Scene) -> np.ndarray:
        """First surface point (H*W, 3) float32 [m] of every pixel-centre ray (NaN:
        none), cast in blocks of rows to keep the temporaries small."""
        xy = pixel_normalised(self.camera)
        out = np.empty((xy.shape[0], 3), np.float32)
        step = 64 * self.camera.width
        for a in range(0, xy.shape[0], step):
            b = min(a + step, xy.shape[0])
            rays = np.concatenate([xy[a:b], np.ones((b - a, 1))], axis=1)
            out[a:b] = scene.cast(rays)[1]
        return out

    @cached_property
    def _pencil(self) -> _Pencil | None:
        return _pencil(self.planes)

    @cached_property
    def _background(self) -> np.ndarray:
        """Grey level of an unlit pixel for each of 65536 equal-probability bins."""
        full, scale = self._range()
        lvl = self.dark * scale + _normal_quantiles() * np.float32(
            self.read_noise * scale
        )
        return np.clip(np.rint(lvl), 0, full).astype(self._dtype())

    def _range(self) -> tuple[float, float]:
        return (255.0, 1.0) if self.bit_depth == 8 else (65535.0, 256.0)

    def _dtype(self) -> type:
        return np.uint8 if self.bit_depth == 8 else np.uint16

    # -- per scene -------------------------------------------------------------------
    def _depth(self, scene: Scene) -> tuple[Float, Float, Float, np.ndarray]:
        """Pixel-centre ray cast of ``scene`` (cached for the last scene asked; the cache
        holds the scene object itself, so a new scene is never taken for an old one)."""
        with self._lock:
            if self._depth_data is not None and self._depth_data[0] is scene:
                return self._depth_data[1]
        data = scene.cast(self.pixel_rays)
        with self._lock:
            self._depth_data = (scene, data)
        return data

    def prepare(self, scene: Scene) -> PreparedScene:
        """The per-scene data of :meth:`render` (kept for the last scene prepared)."""
        with self._lock:
            if self._prepared is not None and self._prepared.scene is scene:
                return self._prepared
        prep = PreparedScene(scene, self._surface32(scene))
        pen = self._pencil
        if pen is not None:
            prep = self._index(prep, pen)
        with self._lock:
            self._prepared = prep
        return prep

    def _index(self, prep: PreparedScene, pen: _Pencil) -> PreparedScene:
        """Sort the pixels by their angle about the planes' axis.

        A plane ``psi_i`` is at signed distance ``s = rho sin(psi - psi_i)`` from a point
        at angle ``psi`` and distance ``rho`` from the axis, and ``|s(p) - s(q)|`` is at
        most the distance ``D`` of p and q across the axis. The band test (``|s| < 5
        sigma + max |s(p) - s(neighbour)|``) can therefore only pass where ``|psi -
        psi_i| < pi/2 (5 sigma + max D) / rho``: that half-width is kept per pixel (in
        float32: 1e-7 rad, far inside the pi/2 margin).
        """
        H, W = self.camera.height, self.camera.width
        q = prep.X32 - pen.S.astype(np.float32)
        c1 = (q @ pen.e1.astype(np.float32)).reshape(H, W)
        c2 = (q @ pen.e2.astype(np.float32)).reshape(H, W)
        del q
        rho = np.hypot(c1, c2)
        psi = np.arctan2(c2, c1)
        psi += np.float32(np.pi / 2 - pen.centre + np.pi / 2)
        np.mod(psi, np.float32(np.pi), out=psi)
        psi += np.float32(pen.centre - np.pi / 2)
        reach = np.zeros((H, W), np.float32)
        for axis in (0, 1):
            d = np.hypot(np.diff(c1, axis=axis), np.diff(c2, axis=axis))
            lo = [slice(None)] * 2
            hi = [slice(None)] * 2
            lo[axis], hi[axis] = slice(None, -1), slice(1, None)
            np.fmax(reach[tuple(lo)], d, out=reach[tuple(lo)])
            np.fmax(reach[tuple(hi)], d, out=reach[tuple(hi)])
        del c1, c2
        reach += np.float32(5.0 * self.laser_sigma)
        with np.errstate(divide="ignore", invalid="ignore"):
            half = np.float32(np.pi / 2) * reach / rho
        del reach, rho
        half = half.ravel()
        psi = psi.ravel()
        ok = np.isfinite(psi) & np.isfinite(half)
        wide = ok & (half > _WIDE_RAD)
        narrow = np.flatnonzero(ok & ~wide).astype(np.int32)
        order = narrow[np.argsort(psi[narrow], kind="stable")]
        return PreparedScene(
            prep.scene,
            prep.X32,
            order,
            psi[order],
            half,
            float(half[order].max(initial=0.0)),
            np.flatnonzero(wide).astype(np.int32),
        )

    # -- per image -------------------------------------------------------------------
    def _lit(
        self, scene: Scene, X: Float, normal: Float, obj: np.ndarray, index: int
    ) -> tuple[Float, Float]:
        """Signed distance from plane ``index`` and the shading factor of points."""
        S = self.planes.source
        assert S is not None
        s = self.planes.distance(X, index)
        to_light = S - X
        cos = np.einsum("ij,ij->i", normal, to_light)
        cos /= np.sqrt(np.einsum("ij,ij->i", to_light, to_light))
        shade = np.clip(cos, 0.0, None) * scene.albedo(obj)
        shade[obj < 0] = 0.0
        if scene.spheres:
            shade[scene.shadowed(X, S, obj)] = 0.0
        return s, shade

    def _band(self, prep: PreparedScene, index: int) -> np.ndarray:
        """Flat indices (sorted) of pixels whose area may receive light from plane
        ``index``: the sheet passes within 5 sigma of the pixel centre, widened by the
        change of the distance to the neighbouring pixels (NaN-safe)."""
        H, W = self.camera.height, self.camera.width
        if prep.order is None:
            cand = None  # every pixel
        else:
            assert prep.psi is not None and prep.half is not None
            pen = self._pencil
            assert pen is not None and prep.wide is not None
            p = pen.psi[index]
            lo, hi = np.searchsorted(prep.psi, [p - prep.reach, p + prep.reach])
            near = prep.order[lo:hi]
            near = near[np.abs(prep.psi[lo:hi] - p) < prep.half[near]]
            cand = np.concatenate([near, prep.wide]).astype(np.intp)
        n = self.planes.n[index].astype(np.float32)
        b = np.float32(self.planes.b[index])
        if cand is None:
            s = (prep.X32 @ n + b).reshape(H, W)
            g = np.zeros_like(s)
            du, dv = np.abs(np.diff(s, axis=1)), np.abs(np.diff(s, axis=0))
            np.fmax(g[:, 1:], du, out=g[:, 1:])
            np.fmax(g[:, :-1], du, out=g[:, :-1])
            np.fmax(g[1:, :], dv, out=g[1:, :])
            np.fmax(g[:-1, :], dv, out=g[:-1, :])
            near = np.abs(s) < np.float32(5.0 * self.laser_sigma) + g
            return np.flatnonzero(near.ravel())
        cand.sort()
        s = prep.X32[cand] @ n + b
        g = np.zeros_like(s)
        col, row = cand % W, cand // W
        for step, ok in (
            (-1, col > 0),
            (1, col < W - 1),
            (-W, row > 0),
            (W, row < H - 1),
        ):
            nb = prep.X32[np.where(ok, cand + step, cand)] @ n + b
            np.fmax(g, np.where(ok, np.abs(s - nb), np.float32(np.nan)), out=g)
        return cand[np.abs(s) < np.float32(5.0 * self.laser_sigma) + g]

    def _subpixel_rays(self, band: np.ndarray) -> Float:
        """Rays (len(band) * ss², 3) through the ``ss x ss`` sub-pixel sample points of
        the pixels ``band``, from the pixel centre's normalised coordinates and their
        central differences to the neighbouring pixels (the distortion's curvature moves
        a sample a third of a pixel from the centre by under 1e-5 px)."""
        H, W = self.camera.height, self.camera.width
        ss = self.supersample
        off = (np.arange(ss) + 0.5) / ss - 0.5
        dv, du = (o.ravel() for o in np.meshgrid(off, off, indexing="ij"))
        g = pixel_normalised(self.camera)
        col, row = band % W, band // W
        left = np.where(col > 0, band - 1, band)
        right = np.where(col < W - 1, band + 1, band)
        up = np.where(row > 0, band - W, band)
        down = np.where(row < H - 1, band + W, band)
        gu = (g[right] - g[left]) / (right - left)[:, None]
        gv = (g[down] - g[up]) / ((down - up) // W)[:, None]
        xy = (
            g[band][:, None, :]
            + du[None, :, None] * gu[:, None, :]
            + dv[None, :, None] * gv[:, None, :]
        ).reshape(-1, 2)
        return np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)

    def render(
        self, scene: Scene | PreparedScene, index: int, rng: np.random.Generator
    ) -> np.ndarray:
        """One stripe image (H, W) of ``scene`` with light plane ``index`` on."""
        H, W = self.camera.height, self.camera.width
        prep = scene if isinstance(scene, PreparedScene) else self.prepare(scene)
        out = self._background[rng.integers(0, 65536, H * W, dtype=np.uint16)]
        band = self._band(prep, int(index))
        if band.size:
            ss2 = self.supersample**2
            _, X, normal, obj = prep.scene.cast(self._subpixel_rays(band))
            s, shade = self._lit(prep.scene, np.nan_to_num(X), normal, obj, int(index))
            val = shade * np.exp(-0.5 * (s / self.laser_sigma) ** 2)
            val = val.reshape(band.size, ss2).mean(axis=1)
            if self.speckle > 0:
                val *= np.clip(
                    1.0 + self.speckle * rng.standard_normal(band.size), 0.0, None
                )
            full, scale = self._range()
            grey = (val * self.peak + self.dark) * scale
            grey += gaussian_noise(rng, band.size, self.read_noise * scale)
            out[band] = np.clip(np.rint(grey), 0, full)
        return out.reshape(H, W)

    def render_scan(
        self, scene: Scene, rng: np.random.Generator, indices: np.ndarray | None = None
    ) -> np.ndarray:
        """Stripe images (M, H, W) for planes ``indices`` (default: all)."""
        idx = np.arange(len(self.planes)) if indices is None else np.asarray(indices)
        prep = self.prepare(scene)
        return np.stack([self.render(prep, int(i), rng) for i in idx])

    def true_stripe(self, scene: Scene, index: int) -> Float:
        """Exact stripe centres (K, 2) ``u, v``: per row, where the lit curve crosses it.

        Rows where the curve is in shadow or crosses several times keep the brightest
        crossing. Sub-pixel positions come from a secant search along the row.
        """
        H, W = self.camera.height, self.camera.width
        _, X, normal, obj = self._depth(scene)
        hit = obj >= 0
        s = np.full(H * W, np.nan)
        shade = np.zeros(H * W)
        s[hit], shade[hit] = self._lit(scene, X[hit], normal[hit], obj[hit], index)
        s2, sh2, ob2 = s.reshape(H, W), shade.reshape(H, W), obj.reshape(H, W)
        cross = (
            (np.sign(s2[:, :-1]) * np.sign(s2[:, 1:]) <= 0)
            & (ob2[:, :-1] == ob2[:, 1:])
            & (ob2[:, :-1] >= 0)
            & (sh2[:, :-1] > 0)
            & (sh2[:, 1:] > 0)
        )
        score = np.where(cross, sh2[:, :-1], -1.0)
        c = np.argmax(score, axis=1)
        rows = np.flatnonzero(score[np.arange(H), c] > 0)
        c = c[rows]
        a = c.astype(float)
        b = a + 1.0
        fa = s2[rows, c]
        fb = s2[rows, c + 1]
        v = rows.astype(float)
        for _ in range(30):  # regula falsi (Illinois) on the continuous column
            with np.errstate(invalid="ignore", divide="ignore"):
                m = np.where(fb != fa, b - fb * (b - a) / (fb - fa), 0.5 * (a + b))
            ray = self.camera.rays(np.stack([m, v], 1))
            _, Xm, _, _ = scene.cast(ray)
            fm = self.planes.distance(Xm, index)
            left = np.sign(fm) == np.sign(fa)
            a = np.where(left, m, a)
            fa = np.where(left, fm, fa)
            fb = np.where(left, 0.5 * fb, fb)
            b = np.where(left, b, m)
            fb = np.where(left, fb, fm)
            fa = np.where(left, fa, 0.5 * fa)
            if np.max(np.abs(b - a), initial=0.0) < 1e-9:
                break
        u = 0.5 * (a + b)
        ok = np.isfinite(u)
        return np.stack([u[ok], v[ok]], 1)
