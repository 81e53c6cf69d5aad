"""Image level: rendered stripes, sub-pixel extraction, scans, calibration (issue 6)."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.sensor import (
    BORDER,
    PlaneSurface,
    Scene,
    StripeRenderer,
    extract_stripes,
    fit_sphere,
    paper_sensor,
    score_centres,
    sphere_scene,
    sphere_stripe_truth,
)


@pytest.fixture(scope="module")
def sensor():
    return paper_sensor()


@pytest.fixture(scope="module")
def renderer(sensor):
    return StripeRenderer(sensor.camera, sensor.planes)


def _match(found, true):
    """Errors in u of the row cross-sections (integer v) against the renderer's rows."""
    rows = found[np.abs(found[:, 1] - np.rint(found[:, 1])) < 1e-9]
    d = dict(zip(true[:, 1].astype(int), true[:, 0]))
    hit = [k for k, v in enumerate(np.rint(rows[:, 1]).astype(int)) if v in d]
    e = rows[hit, 0] - np.array([d[round(rows[k, 1])] for k in hit])
    return e, len(hit), rows.shape[0]


def test_stripe_extraction_is_subpixel_on_rendered_images(sensor, renderer):
    rng = np.random.default_rng(0)
    c = np.array([0.002, -0.001, 0.140])
    scene = sphere_scene(c, 0.015)
    errs = []
    for i in (20, 40, 60):
        img = renderer.render(scene, i, rng)
        assert img.shape == (1024, 1280) and img.dtype == np.uint8
        true = renderer.true_stripe(scene, i)
        found = extract_stripes(img)
        e, n, n_rows = _match(found, true)
        # Where the stripe runs steeper than 45 deg its cross-sections are rows:
        steep = np.abs(np.gradient(true[:, 0], true[:, 1])) <= 1.0
        assert n >= 0.95 * steep.sum() > 300  # almost every such row found ...
        assert n_rows <= true.shape[0] + 5  # ... and no rows that are not there
        errs.append(e)
        # Every centre (rows and, where the stripe turns flat, columns) against the
        # true curve: one per cross-section, none off the stripe.
        s = score_centres(
            found,
            sphere_stripe_truth(sensor.camera, sensor.planes, i, c, 0.015, min_cos=0),
            shape=img.shape,
            margin_px=8,
            cover=sphere_stripe_truth(sensor.camera, sensor.planes, i, c, 0.015),
        )
        assert s.coverage >= 0.97 and s.false == 0.0 and s.per_section <= 1.01
        assert s.rms_px < 0.1
    e = np.concatenate(errs)
    assert abs(np.mean(e)) < 0.02  # px: no bias
    assert np.sqrt(np.mean(e**2)) < 0.15  # px, with speckle and read noise


def test_extraction_ignores_background_and_wide_reflections():
    rng = np.random.default_rng(1)
    H, W = 1024, 1280
    u0 = 640 + 80 * np.sin(np.arange(H) / 150.0)
    U = np.arange(W)[None, :]
    img = 10 + 150 * np.exp(-0.5 * ((U - u0[:, None]) / 1.4) ** 2)
    img[:, 100:400] += 40 * np.exp(-0.5 * ((U[:, 100:400] - 250) / 60.0) ** 2)  # glare
    img[:300] *= 0.0  # rows without a stripe
    img += rng.normal(0, 1.5, img.shape)
    found = extract_stripes(np.clip(img, 0, 255).astype(np.uint8))
    assert found[:, 1].min() >= 300
    e = found[:, 0] - np.interp(found[:, 1], np.arange(H), u0)
    # Centres next to the image border are flagged (the filter's reach is cut there).
    inner = (found[:, 6].astype(int) & BORDER) == 0
    assert np.max(np.abs(e[inner])) < 0.2 and found.shape[0] > 700
    assert np.all(found[~inner, 1] > H - 8) and np.max(np.abs(e)) < 0.3
    # The first method, per row, kept for comparisons, does so too.
    rows = extract_stripes(np.clip(img, 0, 255).astype(np.uint8), method="rows")
    assert rows[:, 1].min() >= 300 and rows.shape[0] > 700


def test_sixteen_bit_images(sensor):
    ren16 = StripeRenderer(sensor.camera, sensor.planes, bit_depth=16)
    rng = np.random.default_rng(2)
    scene = sphere_scene([0.0, 0.0, 0.140], 0.015)
    img = ren16.render(scene, 60, rng)
    assert img.dtype == np.uint16 and img.max() > 255
    e, n, _ = _match(extract_stripes(img), ren16.true_stripe(scene, 60))
    assert n > 300 and np.sqrt(np.mean(e**2)) < 0.15


@pytest.mark.slow  # (a whole image pipeline: make test-slow; `make test` under 90 s)
def test_scan_of_a_ceramic_sphere_with_the_true_geometry(sensor, renderer):
    """Extraction + undistortion + Eq. (5) + sphere fit, without calibration error."""
    rng = np.random.default_rng(3)
    c = np.array([0.003, -0.002, 0.140])
    R = 0.015002
    imgs = renderer.render_scan(sphere_scene(c, R), rng)
    cloud = sensor.scan(imgs, jobs=2)
    assert cloud.points.shape[0] > 20_000  # full-resolution scan: tens of thousands
    serial = sensor.scan(imgs, jobs=1)  # threads change nothing
    np.testing.assert_array_equal(cloud.points, serial.points)
    np.testing.assert_array_equal(cloud.plane, serial.plane)
    f = fit_sphere(cloud.points)
    assert abs(f.radius - R) < 3e-6
    assert np.linalg.norm(f.center - c) < 4e-6
    assert f.rms < 15e-6


def test_renderer_sees_shadows_and_planes(sensor, renderer):
    rng = np.random.default_rng(5)
    T = np.eye(4)
    T[:3, 3] = [0, 0, 0.125]
    plane = Scene(
        planes=(PlaneSurface(np.array([0, 0, 0.125]), np.array([0, 0, 1.0])),)
    )
    true = renderer.true_stripe(plane, 60)
    assert true.shape[0] == 1024  # a flat target: the stripe crosses every row
    # A sphere in front of the target casts a shadow: the stripe is interrupted.
    both = Scene(
        spheres=sphere_scene([0.02, 0.0, 0.09], 0.006).spheres, planes=plane.planes
    )
    img = renderer.render(both, 60, rng)
    assert extract_stripes(img).shape[0] < 1000


def test_stripes_of_many_images_on_threads_read_lazily(sensor, renderer):
    """extract_stripes_all: the serial results in order, None kept, each image taken from
    the sequence once (in the worker threads), an error raised with its message."""
    import threading

    from kinecal.errors import DataError
    from kinecal.sensor import extract_stripes_all

    rng = np.random.default_rng(4)
    imgs = renderer.render_scan(sphere_scene([0.0, 0.0, 0.14], 0.015), rng, [10, 60])
    taken: list[tuple[int, str]] = []

    class Lazy:
        def __init__(self, items):
            self.items = items

        def __len__(self):
            return len(self.items)

        def __getitem__(self, i):
            taken.append((i, threading.current_thread().name))
            return self.items[i]

    items = [imgs[0], None, imgs[1], imgs[0]]
    out = extract_stripes_all(Lazy(items), jobs=2)
    assert out[1] is None
    for k in (0, 2, 3):
        np.testing.assert_array_equal(out[k], extract_stripes(items[k]))
    assert sorted(i for i, _ in taken) == [0, 1, 2, 3]
    assert all(name != threading.current_thread().name for _, name in taken)
    with pytest.raises(DataError):
        extract_stripes_all([imgs[0], np.zeros((4, 4, 3))], jobs=2)
