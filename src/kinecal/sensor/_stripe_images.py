"""Synthetic laser-stripe images with exact centres, and the score of extracted centres.

The rotary sensor's renderer (:class:`~kinecal.sensor.StripeRenderer`) only makes what
the sensor sees: near-vertical stripes on spheres and planes. Extractors must also work
on stripes of any direction, curved, under strong speckle, on background gradients, next
to reflections and when saturated; :func:`synthetic_stripe` draws such images with the
true centre line known analytically. The intensity of a pixel is

.. math::

    I(p) = \\mathrm{clip}\\Big(b + g \\cdot p
        + \\big[A\\, e^{-d(p)^2 / 2\\sigma^2}
        + A_r\\, e^{-(d(p) - o_r)^2 / 2\\sigma_r^2}\\big]\\, S(p) + \\epsilon\\Big)

averaged over the pixel area (``supersample`` x ``supersample`` points), with ``d`` the
signed distance from the centre line (a straight line or a circular arc), ``A`` the
stripe's amplitude and ``sigma`` its Gaussian width, ``A_r, o_r, sigma_r`` an optional
secondary reflection parallel to the stripe, ``b + g.p`` the background (level and
gradient), ``S`` multiplicative speckle (Gamma-distributed with shape ``k``: mean 1,
contrast ``1/sqrt(k)``; one value per pixel or correlated over ``speckle_grain_px``) and
``epsilon`` read noise; the result is rounded and clipped to the bit depth (clipping is
saturation). The true centre of every cross-section is ``d = 0``.

:func:`score_centres` compares extracted centres with a true centre line given as a dense
polyline: the distance of each centre along the normal of the true line, the share of
the true cross-sections found (one per image row where the line runs more vertically
than horizontally, one per column elsewhere) and the false centres (further than
``false_px`` from the line). :func:`sphere_stripe_truth` gives the true line of a stripe
rendered by :class:`~kinecal.sensor.StripeRenderer` on a sphere, in any direction.

Pixel-centre convention: pixel (row v, column u) spans ``u +- 0.5, v +- 0.5``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinecal.errors import ConfigError
from kinecal.sensor._camera import Camera
from kinecal.sensor._planes import LightPlanes
from kinecal.typing import Float

__all__ = [
    "StripeScore",
    "StripeSpec",
    "score_centres",
    "sphere_stripe_truth",
    "synthetic_stripe",
]


@dataclass(frozen=True)
class StripeSpec:
    """One synthetic stripe image (lengths in pixels, levels in 8-bit grey levels).

    ``angle_deg`` is the stripe's direction at ``center_px`` from the image's v axis
    (down) towards its u axis (right): 0 is vertical, 90 horizontal. ``radius_px`` bends
    it into a circular arc (``inf``: straight; the centre of curvature is on the +normal
    side, normal ``(cos a, -sin a)``). ``half_length_px`` limits it to that arc length on
    both sides of ``center_px``. Levels scale by 257 for 16-bit images.
    """

    shape: tuple[int, int] = (1024, 1280)
    angle_deg: float = 0.0
    radius_px: float = np.inf
    center_px: tuple[float, float] | None = None  # (u, v); default: the image centre
    half_length_px: float = np.inf
    sigma_px: float = 1.6
    amplitude: float = 150.0
    speckle_k: float = np.inf  # Gamma shape of the speckle; inf: none
    speckle_grain_px: float = 0.0  # 0: independent pixels
    background: float = 8.0
    gradient: tuple[float, float] = (0.0, 0.0)  # grey levels per pixel along u, v
    reflection_offset_px: float = 0.0  # 0: no reflection
    reflection_rel: float = 0.3  # its amplitude relative to the stripe's
    reflection_sigma_px: float = 2.5
    read_noise: float = 1.2
    bit_depth: int = 8
    supersample: int = 4

    def __post_init__(self) -> None:
        if self.bit_depth not in (8, 16):
            raise ConfigError(f"bit_depth must be 8 or 16, got {self.bit_depth}")
        if self.sigma_px <= 0 or self.reflection_sigma_px <= 0:
            raise ConfigError(f"sigma_px must be positive, got {self.sigma_px}")
        if self.radius_px <= 0 or self.speckle_k <= 0:
            raise ConfigError("radius_px and speckle_k must be positive")
        if self.supersample < 1:
            raise ConfigError(f"supersample must be >= 1, got {self.supersample}")

    @property
    def center(self) -> Float:
        H, W = self.shape
        c = self.center_px if self.center_px is not None else ((W - 1) / 2, (H - 1) / 2)
        return np.asarray(c, float)

    @property
    def tangent(self) -> Float:
        a = np.radians(self.angle_deg)
        return np.array([np.sin(a), np.cos(a)])

    @property
    def normal(self) -> Float:
        a = np.radians(self.angle_deg)
        return np.array([np.cos(a), -np.sin(a)])

    def distance(self, uv: Float) -> tuple[Float, Float]:
        """Signed distance from the centre line and arc length along it, of points (N, 2)."""
        rel = np.asarray(uv, float) - self.center
        n, t = self.normal, self.tangent
        if np.isinf(self.radius_px):
            return rel @ n, rel @ t
        R = self.radius_px
        c_rel = rel - R * n  # from the centre of curvature
        r = np.hypot(c_rel[:, 0], c_rel[:, 1])
        ang = np.arctan2(c_rel @ t, -(c_rel @ n))
        return R - r, R * ang

    def truth(self, step: float = 0.05) -> Float:
        """The true centre line inside the image: a dense polyline (N, 2) ``u, v``."""
        H, W = self.shape
        L = float(np.hypot(H, W))
        half = min(
            self.half_length_px,
            L if np.isinf(self.radius_px) else np.pi * self.radius_px,
        )
        s = np.arange(-half, half + step, step)
        n, t, c = self.normal, self.tangent, self.center
        if np.isinf(self.radius_px):
            pts = c + s[:, None] * t
        else:
            R = self.radius_px
            ang = s / R
            pts = c + R * n + R * (np.sin(ang)[:, None] * t - np.cos(ang)[:, None] * n)
        inside = (
            (pts[:, 0] >= -0.5)
            & (pts[:, 0] <= W - 0.5)
            & (pts[:, 1] >= -0.5)
            & (pts[:, 1] <= H - 0.5)
        )
        return pts[inside]


def synthetic_stripe(spec: StripeSpec, rng: np.random.Generator) -> np.ndarray:
    """One grey image (H, W), uint8 or uint16, of the stripe ``spec`` describes."""
    H, W = spec.shape
    scale = 1.0 if spec.bit_depth == 8 else 257.0
    full = 255.0 if spec.bit_depth == 8 else 65535.0
    v, u = np.mgrid[0:H, 0:W]
    img = (spec.background + spec.gradient[0] * u + spec.gradient[1] * v).astype(
        np.float64
    )
    uv = np.stack([u.ravel(), v.ravel()], 1).astype(float)
    d, _ = spec.distance(uv)
    reach = 6.0 * max(spec.sigma_px, spec.reflection_sigma_px) + 1.5
    reach += abs(spec.reflection_offset_px)
    band = np.flatnonzero(np.abs(d) < reach)
    if band.size:
        ss = spec.supersample
        off = (np.arange(ss) + 0.5) / ss - 0.5
        du, dv = np.meshgrid(off, off)
        sub = uv[band, None, :] + np.stack([du.ravel(), dv.ravel()], 1)[None]
        ds, s_arc = spec.distance(sub.reshape(-1, 2))
        inside = np.abs(s_arc) <= spec.half_length_px
        val = np.exp(-0.5 * (ds / spec.sigma_px) ** 2)
        if spec.reflection_offset_px:
            val += spec.reflection_rel * np.exp(
                -0.5
                * ((ds - spec.reflection_offset_px) / spec.reflection_sigma_px) ** 2
            )
        val = (val * inside).reshape(band.size, ss * ss).mean(axis=1)
        val *= spec.amplitude * _speckle(spec, band, rng)
        img.ravel()[band] += val
    img *= scale
    img += rng.normal(0.0, spec.read_noise * scale, img.shape)
    np.rint(img, out=img)
    np.clip(img, 0, full, out=img)
    return img.astype(np.uint8 if spec.bit_depth == 8 else np.uint16)


def _speckle(spec: StripeSpec, band: np.ndarray, rng: np.random.Generator) -> Float:
    """Multiplicative speckle (mean 1) at the pixels ``band`` (flat indices)."""
    if np.isinf(spec.speckle_k):
        return np.ones(band.size)
    k = spec.speckle_k
    if spec.speckle_grain_px <= 0:
        return rng.gamma(k, 1.0 / k, band.size)
    # Correlated speckle: the mean of k intensities of a low-passed complex Gaussian field
    # (fully developed speckle, exponential intensity, grain ~ the low-pass width).
    from kinecal.sensor._cv import require_cv2

    cv2 = require_cv2("correlated speckle")
    W = spec.shape[1]
    rows = band // W
    r0, r1 = int(rows.min()), int(rows.max()) + 1
    acc = np.zeros((r1 - r0, W))
    for _ in range(int(np.ceil(k))):
        re = rng.standard_normal((r1 - r0, W)).astype(np.float32)
        im = rng.standard_normal((r1 - r0, W)).astype(np.float32)
        g = spec.speckle_grain_px
        re = cv2.GaussianBlur(re, (0, 0), g)
        im = cv2.GaussianBlur(im, (0, 0), g)
        acc += re.astype(float) ** 2 + im.astype(float) ** 2
    acc /= acc.mean()
    return acc[rows - r0, band % W]


@dataclass(frozen=True)
class StripeScore:
    """Extracted centres against the true centre line (distances in pixels).

    ``coverage``: share of the true cross-sections with a centre within ``match_px``;
    ``rms_px``, ``bias_px``, ``max_px``: distance along the true line's normal of the
    centres that are not false (signed: + along the normal of :meth:`StripeSpec.normal`
    for synthetic stripes, along ``(t_v, -t_u)`` of the polyline otherwise); ``false``:
    share of the centres further than ``false_px`` from the line; ``per_section``:
    centres (not false) within ``match_px`` of a true cross-section, per cross-section
    found (1 for one centre per cross-section).
    """

    n_true: int
    n_found: int
    coverage: float
    rms_px: float
    bias_px: float
    max_px: float
    false: float
    per_section: float

    def as_dict(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.__dict__.items()}


def score_centres(
    uv: Float,
    truth: Float,
    *,
    false_px: float = 1.0,
    match_px: float = 1.0,
    margin_px: float = 0.0,
    shape: tuple[int, int] | None = None,
    cover: Float | None = None,
) -> StripeScore:
    """Score centres ``uv`` (K, >=2) against a true line, a dense polyline (N, 2).

    The polyline's samples must be much closer than a pixel (:meth:`StripeSpec.truth`
    gives 0.05 px). With ``shape`` and ``margin_px``, true cross-sections within
    ``margin_px`` of the image border are not counted (an extractor's filters need
    room), nor are centres there. ``cover``: the part of the line whose cross-sections
    count for the coverage (default: all of ``truth``; e.g. where a rendered stripe is
    bright enough to be seen), while distances are measured to all of ``truth``.
    """
    from scipy.spatial import cKDTree

    P = np.asarray(truth, float)
    Q = P if cover is None else np.asarray(cover, float)
    if P.shape[0] < 2 or Q.shape[0] < 2:
        nan = float("nan")
        return StripeScore(0, len(uv), nan, nan, nan, nan, nan, nan)
    N = _normals(P)
    sections = _sections(Q)
    C = np.asarray(uv, float)[:, :2]
    if shape is not None and margin_px > 0:
        H, W = shape

        def inner(X: Float) -> np.ndarray:
            return (
                (X[:, 0] >= margin_px - 0.5)
                & (X[:, 0] <= W - 0.5 - margin_px)
                & (X[:, 1] >= margin_px - 0.5)
                & (X[:, 1] <= H - 0.5 - margin_px)
            )

        sections = sections[inner(sections)]
        C = C[inner(C)]
    tree = cKDTree(P)
    dist, idx = tree.query(C) if C.size else (np.zeros(0), np.zeros(0, int))
    # Along the local normal: exact to first order between the samples.
    d = np.einsum("ij,ij->i", C - P[idx], N[idx]) if C.size else np.zeros(0)
    false = dist > false_px
    ok = d[~false]
    if sections.size and ok.size:
        near = cKDTree(C[~false]).query(sections, distance_upper_bound=match_px)[0]
        found = np.isfinite(near)
        # centres at the cross-sections counted (not those beyond ``cover``)
        at = cKDTree(sections).query(C[~false], distance_upper_bound=match_px)[0]
        n_at = int(np.isfinite(at).sum())
    else:
        found = np.zeros(sections.shape[0], bool)
        n_at = 0
    n_true = sections.shape[0]
    return StripeScore(
        n_true=n_true,
        n_found=C.shape[0],
        coverage=float(found.mean()) if n_true else float("nan"),
        rms_px=float(np.sqrt(np.mean(ok**2))) if ok.size else float("nan"),
        bias_px=float(np.mean(ok)) if ok.size else float("nan"),
        max_px=float(np.max(np.abs(ok))) if ok.size else float("nan"),
        false=float(false.mean()) if C.shape[0] else 0.0,
        per_section=float(n_at / max(found.sum(), 1)),
    )


def _normals(P: Float) -> Float:
    """Unit normals (N, 2) ``(t_v, -t_u)`` of a dense polyline (N, 2)."""
    T = np.gradient(P, axis=0)
    T /= np.linalg.norm(T, axis=1, keepdims=True)
    return np.stack([T[:, 1], -T[:, 0]], 1)


def _sections(P: Float) -> Float:
    """Where a dense polyline crosses integer rows (where it runs steeper than 45 deg)
    and integer columns (elsewhere): its cross-sections (M, 2)."""
    N = _normals(P)
    steep = np.abs(N[:, 0]) >= np.abs(N[:, 1])
    gap = np.hypot(*(P[1:] - P[:-1]).T) < 0.5  # not across a gap of the line
    cross = []
    for axis, keep in ((1, steep), (0, ~steep)):
        a, b = P[:-1, axis], P[1:, axis]
        k = np.flatnonzero((np.floor(a) != np.floor(b)) & keep[:-1] & keep[1:] & gap)
        x = np.maximum(np.floor(a[k]), np.floor(b[k]))  # the integer crossed
        f = (x - a[k]) / (b[k] - a[k])
        cross.append(P[k] + f[:, None] * (P[k + 1] - P[k]))
    return np.concatenate(cross)


def sphere_stripe_truth(
    camera: Camera,
    planes: LightPlanes,
    index: int,
    center: Float,
    radius: float,
    *,
    min_cos: float = 0.1,
) -> Float:
    """True centre line (N, 2) of light plane ``index`` on a sphere, as rendered.

    The plane cuts the sphere (centre [m] and radius [m], camera frame) in a circle; its
    points that face the camera and the light source (``planes.source``) at more than
    ``acos(min_cos)`` from grazing (the renderer shades by that cosine: at 0.1 the
    stripe has a tenth of its brightness), projected with the camera's distortion,
    sampled densely (about 0.05 px apart), inside the image.
    """
    n = np.asarray(planes.n[index], float)
    b = float(planes.b[index])
    c = np.asarray(center, float)
    h = float(n @ c + b)  # distance of the centre from the plane
    if abs(h) >= radius:
        return np.zeros((0, 2))
    q = c - h * n  # the circle's centre
    rc = np.sqrt(radius**2 - h**2)
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-9:
        e1 = np.cross(n, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    f = max(camera.fx, camera.fy)
    m = int(np.ceil(2 * np.pi * rc * f / float(q[2]) / 0.05))
    ang = np.linspace(0, 2 * np.pi, m, endpoint=False)
    X = q + rc * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    normal = (X - c) / radius
    if planes.source is None:
        raise ConfigError("sphere_stripe_truth: the planes need their light source")
    S = np.asarray(planes.source, float)
    to_cam = -X / np.linalg.norm(X, axis=1, keepdims=True)
    to_light = (S - X) / np.linalg.norm(S - X, axis=1, keepdims=True)
    seen = np.einsum("ij,ij->i", normal, to_cam) > min_cos
    lit = np.einsum("ij,ij->i", normal, to_light) > min_cos
    keep = seen & lit
    if not keep.any():
        return np.zeros((0, 2))
    # Start the polyline at a gap so that it does not jump.
    first = int(np.argmin(keep)) if not keep.all() else 0
    order = np.roll(np.arange(m), -first)
    X = X[order][keep[order]]
    uv = camera.project(X)
    H, W = camera.height, camera.width
    inside = (
        (uv[:, 0] >= -0.5)
        & (uv[:, 0] <= W - 0.5)
        & (uv[:, 1] >= -0.5)
        & (uv[:, 1] <= H - 0.5)
    )
    return uv[inside]
