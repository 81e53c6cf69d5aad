"""Image level: rendered stripes, sub-pixel extraction, scans, calibration (issue 6)."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.sensor import (
    PlaneSurface,
    Scene,
    StripeRenderer,
    extract_stripes,
    fit_sphere,
    paper_sensor,
    sphere_scene,
)


@pytest.fixture(scope="module")
def sensor():
    return paper_sensor()


@pytest.fixture(scope="module")
def renderer(sensor):
    return StripeRenderer(sensor.camera, sensor.planes)


def _match(found, true):
    d = dict(zip(true[:, 1].astype(int), true[:, 0]))
    rows = [k for k, v in enumerate(found[:, 1].astype(int)) if v in d]
    return found[rows, 0] - np.array([d[int(found[k, 1])] for k in rows]), len(rows)


def test_stripe_extraction_is_subpixel_on_rendered_images(sensor, renderer):
    rng = np.random.default_rng(0)
    scene = sphere_scene([0.002, -0.001, 0.140], 0.015)
    errs = []
    for i in (20, 40, 60):
        img = renderer.render(scene, i, rng)
        assert img.shape == (1024, 1280) and img.dtype == np.uint8
        true = renderer.true_stripe(scene, i)
        found = extract_stripes(img)
        e, n = _match(found, true)
        assert n >= 0.95 * true.shape[0] > 300  # almost every lit row found ...
        assert (
            found.shape[0] <= true.shape[0] + 5
        )  # ... and no stripes that are not there
        errs.append(e)
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
    e = found[:, 0] - u0[found[:, 1].astype(int)]
    assert np.max(np.abs(e)) < 0.2 and found.shape[0] > 700


def test_sixteen_bit_images(sensor):
    ren16 = StripeRenderer(sensor.camera, sensor.planes, bit_depth=16)
    rng = np.random.default_rng(2)
    scene = sphere_scene([0.0, 0.0, 0.140], 0.015)
    img = ren16.render(scene, 60, rng)
    assert img.dtype == np.uint16 and img.max() > 255
    e, n = _match(extract_stripes(img), ren16.true_stripe(scene, 60))
    assert n > 300 and np.sqrt(np.mean(e**2)) < 0.15


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
