"""Image-level simulator of the rotary laser sensor: stripe and chessboard images.

Scenes are spheres and planes in the camera frame (metres). A pixel sees the first
surface its ray hits; a light plane lights a surface point with a Gaussian sheet profile
across the plane (``laser_sigma``), Lambertian shading, shadows from the light source and
multiplicative speckle; the camera adds a dark level, read noise, saturation and
quantisation. Each pixel integrates over its area (``supersample`` x ``supersample``
sub-pixel rays), so the stripe centres carry no rendering bias beyond that of real optics.

Rendering a stripe only traces sub-pixel rays in the band of pixels near the lit curve,
so a 1280 x 1024 image takes tens of milliseconds. :meth:`StripeRenderer.true_stripe`
gives the exact centre per row (where the ray meets the light plane on the surface), the
ground truth for extraction, and the fast point-level mode of the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np

from kinecal.errors import ConfigError
from kinecal.sensor._camera import Camera
from kinecal.sensor._cv import require_cv2
from kinecal.sensor._planes import LightPlanes
from kinecal.typing import Float

__all__ = [
    "ChessboardTarget",
    "PlaneSurface",
    "Scene",
    "SphereSurface",
    "StripeRenderer",
    "render_chessboard",
]


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
class ChessboardTarget:
    """A chessboard of ``cols x rows`` inner corners, ``square`` [m], on a white panel.

    Board frame: origin at the first inner corner, x along the ``cols`` direction, z out
    of the printed face. The white margin is ``margin`` squares wide around the pattern.
    """

    cols: int = 10  # one even, one odd count: the pattern's orientation is unambiguous
    rows: int = 7
    square: float = 2.5e-3
    margin: float = 1.5

    def object_points(self) -> Float:
        """Inner corners (rows*cols, 3) in OpenCV's order (row-major over the pattern)."""
        j, i = np.mgrid[0 : self.rows, 0 : self.cols]
        return np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], 1) * self.square


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
    _scene: Scene | None = field(default=None, repr=False)
    _depth_data: tuple[Float, Float, Float, np.ndarray] | None = field(
        default=None, repr=False
    )
    _x32_data: Float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.bit_depth not in (8, 16):
            raise ConfigError(f"bit_depth must be 8 or 16, got {self.bit_depth}")
        if self.planes.source is None:
            raise ConfigError("the renderer needs the light source of the planes")

    @cached_property
    def pixel_rays(self) -> Float:
        """Rays (H*W, 3) through every pixel centre."""
        xy = _pixel_normalised(self.camera)
        return np.concatenate([xy, np.ones_like(xy[:, :1])], axis=1)

    def _depth(self, scene: Scene) -> tuple[Float, Float, Float, np.ndarray]:
        """Pixel-centre ray cast of ``scene`` (cached for the last scene rendered).

        The cache holds the scene object itself, so a new scene can never be mistaken
        for an old one that happened to live at the same address.
        """
        if self._scene is not scene:
            self._scene = scene
            self._depth_data = scene.cast(self.pixel_rays)
            self._x32_data = None
        assert self._depth_data is not None
        return self._depth_data

    def _lit(
        self, scene: Scene, X: Float, normal: Float, obj: np.ndarray, index: int
    ) -> tuple[Float, Float]:
        """Signed distance from plane ``index`` and the shading factor of points."""
        S = self.planes.source
        assert S is not None
        s = self.planes.distance(X, index)
        to_light = S - X
        to_light /= np.linalg.norm(to_light, axis=1, keepdims=True)
        cos = np.einsum("ij,ij->i", normal, to_light)
        shade = np.clip(cos, 0.0, None) * scene.albedo(obj)
        shade[obj < 0] = 0.0
        if scene.spheres:
            shade[scene.shadowed(X, S, obj)] = 0.0
        return s, shade

    def _band(self, scene: Scene, index: int) -> np.ndarray:
        """Flat indices of pixels whose area may receive light from plane ``index``."""
        X32 = self._x32(scene)
        H, W = self.camera.height, self.camera.width
        n = self.planes.n[index].astype(np.float32)
        s = (X32 @ n + np.float32(self.planes.b[index])).reshape(
            H, W
        )  # NaN: no surface
        a = np.abs(s)
        # A pixel may see light if the sheet passes within 5 sigma of its area: widen the
        # test by the change of the distance to the neighbouring pixels (NaN-safe fmax).
        du = np.abs(np.diff(s, axis=1))
        dv = np.abs(np.diff(s, axis=0))
        g = np.zeros_like(s)
        np.fmax(g[:, 1:], du, out=g[:, 1:])
        np.fmax(g[:, :-1], du, out=g[:, :-1])
        np.fmax(g[1:, :], dv, out=g[1:, :])
        np.fmax(g[:-1, :], dv, out=g[:-1, :])
        near = a < np.float32(5.0 * self.laser_sigma) + g
        return np.flatnonzero(near.ravel())

    def _x32(self, scene: Scene) -> Float:
        X = self._depth(scene)[1]
        if self._x32_data is None:
            self._x32_data = X.astype(np.float32)
        return self._x32_data

    def render(self, scene: Scene, index: int, rng: np.random.Generator) -> np.ndarray:
        """One stripe image (H, W) of ``scene`` with light plane ``index`` on."""
        H, W = self.camera.height, self.camera.width
        signal = np.zeros(H * W)
        band = self._band(scene, index)
        if band.size:
            ss = self.supersample
            off = (np.arange(ss) + 0.5) / ss - 0.5
            du, dv = np.meshgrid(off, off)
            u = (band % W)[:, None] + du.ravel()[None, :]
            v = (band // W)[:, None] + dv.ravel()[None, :]
            rays = self.camera.rays(np.stack([u.ravel(), v.ravel()], 1))
            _, X, normal, obj = scene.cast(rays)
            s, shade = self._lit(scene, np.nan_to_num(X), normal, obj, index)
            val = shade * np.exp(-0.5 * (s / self.laser_sigma) ** 2)
            val = val.reshape(band.size, ss * ss).mean(axis=1)
            if self.speckle > 0:
                val *= np.clip(
                    1.0 + self.speckle * rng.standard_normal(band.size), 0.0, None
                )
            signal[band] = val
        return self._sensor(signal.reshape(H, W) * self.peak, rng)

    def _sensor(self, img: Float, rng: np.random.Generator) -> np.ndarray:
        full = 255.0 if self.bit_depth == 8 else 65535.0
        scale = 1.0 if self.bit_depth == 8 else 256.0
        out = rng.standard_normal(img.shape, dtype=np.float32)
        out *= np.float32(self.read_noise * scale)
        out += (img * scale).astype(np.float32)
        out += np.float32(self.dark * scale)
        np.rint(out, out=out)
        np.clip(out, 0, full, out=out)
        return out.astype(np.uint8 if self.bit_depth == 8 else np.uint16)

    def render_scan(
        self, scene: Scene, rng: np.random.Generator, indices: np.ndarray | None = None
    ) -> np.ndarray:
        """Stripe images (M, H, W) for planes ``indices`` (default: all)."""
        idx = np.arange(len(self.planes)) if indices is None else np.asarray(indices)
        return np.stack([self.render(scene, int(i), rng) for i in idx])

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


@lru_cache(maxsize=2)
def _pixel_normalised(camera: Camera) -> Float:
    """Undistorted normalised coordinates (H*W, 2) of every pixel centre (row-major).

    Shared by the stripe and the chessboard renderers: the Newton undistortion of a full
    1280 x 1024 grid is the costly step, done once per camera.
    """
    H, W = camera.height, camera.width
    v, u = np.mgrid[0:H, 0:W]
    xy = camera.normalised(np.stack([u.ravel(), v.ravel()], 1).astype(float))
    xy.setflags(write=False)
    return xy


@lru_cache(maxsize=4)
def _ideal_map(camera: Camera, scale: int) -> tuple[np.ndarray, np.ndarray]:
    """For every pixel, where its undistorted ray lands in an ideal image ``scale`` x finer."""
    H, W = camera.height, camera.width
    xy = _pixel_normalised(camera)
    ui = camera.fx * xy[:, 0] + camera.u0
    vi = camera.fy * xy[:, 1] + camera.v0
    mx = (scale * (ui + 0.5) - 0.5).reshape(H, W).astype(np.float32)
    my = (scale * (vi + 0.5) - 0.5).reshape(H, W).astype(np.float32)
    return mx, my


@lru_cache(maxsize=4)
def _board_texture(
    target: ChessboardTarget, px_per_m: float, black: float, white: float
) -> tuple[np.ndarray, float]:
    """The printed panel as an image (rows along board y) and its first texel's x = y."""
    lo = -(target.margin + 1.0) * target.square
    hi_x = (target.cols + target.margin) * target.square
    hi_y = (target.rows + target.margin) * target.square
    nx = int(np.ceil((hi_x - lo) * px_per_m))
    ny = int(np.ceil((hi_y - lo) * px_per_m))
    x = lo + (np.arange(nx) + 0.5) / px_per_m
    y = lo + (np.arange(ny) + 0.5) / px_per_m
    sq = target.square
    ix = np.floor(x / sq)
    iy = np.floor(y / sq)
    inx = (x >= -sq) & (x < target.cols * sq)
    iny = (y >= -sq) & (y < target.rows * sq)
    dark = ((ix[None, :] + iy[:, None]) % 2 == 0) & inx[None, :] & iny[:, None]
    tex = np.where(dark, black, white).astype(np.float32)
    return tex, lo


def render_chessboard(
    camera: Camera,
    T_cam_board: Float,
    rng: np.random.Generator,
    target: ChessboardTarget | None = None,
    *,
    black: float = 25.0,
    white: float = 215.0,
    surround: float = 60.0,
    read_noise: float = 1.5,
    supersample: int = 3,
    blur_px: float = 0.7,
) -> np.ndarray:
    """A grey 8-bit image (H, W) of a chessboard panel seen by ``camera``.

    The panel is drawn by its exact homography into an ideal (distortion-free) image
    ``supersample`` times finer, box-filtered over one output pixel (pixel integration),
    then sampled through the lens distortion at every output pixel; optics blur
    (``blur_px``, Gaussian sigma) and read noise follow.
    """
    cv2 = require_cv2("rendering chessboard images")

    tgt = target or ChessboardTarget()
    s = int(supersample)
    if s < 1 or s % 2 == 0:
        raise ConfigError(f"supersample must be an odd positive integer, got {s}")
    H, W = camera.height, camera.width
    f_img = max(camera.fx, camera.fy) * s / max(float(T_cam_board[2, 3]), 1e-3)
    ppm = float(
        2 ** np.ceil(np.log2(1.5 * f_img))
    )  # texels per metre, a few sizes only
    tex, lo = _board_texture(tgt, ppm, black, white)
    # texel (i, j) centre -> board (x, y) -> camera -> fine ideal pixel (a, b)
    A = np.array(
        [[1 / ppm, 0, lo + 0.5 / ppm], [0, 1 / ppm, lo + 0.5 / ppm], [0, 0, 1]]
    )
    P = np.column_stack([T_cam_board[:3, 0], T_cam_board[:3, 1], T_cam_board[:3, 3]])
    Ks = np.array(
        [
            [s * camera.fx, 0, s * (camera.u0 + 0.5) - 0.5],
            [0, s * camera.fy, s * (camera.v0 + 0.5) - 0.5],
            [0, 0, 1],
        ]
    )
    Hm = Ks @ P @ A
    fine = cv2.warpPerspective(
        tex,
        Hm,
        (W * s, H * s),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=surround,
    )
    fine = cv2.blur(fine, (s, s))
    mx, my = _ideal_map(camera, s)
    img = cv2.remap(
        fine,
        mx,
        my,
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=surround,
    )
    if blur_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur_px)
    noisy = img + rng.standard_normal(img.shape, dtype=np.float32) * np.float32(
        read_noise
    )
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
