"""The image simulator made fast and lean (issue 24): the per-scene angular index finds
exactly the pixels the full test finds, the sub-pixel rays and the table noise are
exact enough, sessions render on access, the same images whatever the order or threads."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from kinecal.sensor import (
    PlaneSurface,
    RenderedImages,
    Scene,
    StripeRenderer,
    paper_sensor,
    rotary_planes,
    simulate_calibration,
    sphere_scene,
)
from kinecal.sensor._board import gaussian_noise
from kinecal.sensor._render import PreparedScene


@pytest.fixture(scope="module")
def renderer():
    sen = paper_sensor()
    return StripeRenderer(sen.camera, sen.planes)


def _scenes():
    n = np.array([0.12, -0.05, 1.0])
    yield Scene(
        planes=(PlaneSurface(np.array([0.0, 0.0, 0.125]), n / np.linalg.norm(n)),)
    )
    yield sphere_scene([0.002, -0.001, 0.14], 0.015)
    ball = sphere_scene([0.02, 0.0, 0.09], 0.006).spheres  # shadow on the plane
    yield Scene(
        spheres=ball,
        planes=(PlaneSurface(np.array([0, 0, 0.125]), np.array([0, 0, 1.0])),),
    )


@pytest.mark.slow  # 1.4-4.3 s: in test-slow, to keep make test within its budget
def test_angular_index_finds_exactly_the_band_of_the_full_test(renderer):
    for scene in _scenes():
        prep = renderer.prepare(scene)
        assert prep.order is not None
        full = PreparedScene(scene, prep.X32)  # no index: every pixel tested
        for i in range(0, 120, 7):
            np.testing.assert_array_equal(
                renderer._band(prep, i), renderer._band(full, i)
            )


def test_planes_without_a_common_axis_fall_back_to_the_full_test():
    sen = paper_sensor()
    pl = rotary_planes()
    n = pl.n.copy()
    n[5] = n[5] + [0.0, 0.01, 0.0]
    n[5] /= np.linalg.norm(n[5])
    from kinecal.sensor import LightPlanes

    ren = StripeRenderer(sen.camera, LightPlanes(n, pl.b, pl.source))
    prep = ren.prepare(next(_scenes()))
    assert prep.order is None
    assert ren.render(prep, 60, np.random.default_rng(0)).max() > 100


def test_subpixel_rays_from_the_pixel_grid_are_exact(renderer):
    cam = renderer.camera
    W = cam.width
    band = np.array([0, 7, W - 1, 512 * W + 640, 1023 * W, 1024 * W - 1, 700 * W + 300])
    rays = renderer._subpixel_rays(band)
    off = (np.arange(3) + 0.5) / 3 - 0.5
    dv, du = (o.ravel() for o in np.meshgrid(off, off, indexing="ij"))
    u = ((band % W)[:, None] + du).ravel()
    v = ((band // W)[:, None] + dv).ravel()
    exact = cam.rays(np.stack([u, v], 1))
    assert np.max(np.abs(rays - exact)) * cam.fx < 1e-4  # px


def test_table_noise_is_normal():
    x = gaussian_noise(np.random.default_rng(0), 400_000, 1.5)
    assert x.dtype == np.float32
    assert abs(x.mean()) < 0.01 and x.std() == pytest.approx(1.5, rel=0.01)
    q = np.quantile(x / 1.5, [0.0228, 0.1587, 0.8413, 0.9772])
    np.testing.assert_allclose(q, [-2, -1, 1, 2], atol=0.02)


def test_session_renders_on_access_the_same_in_any_order_and_thread():
    sen = paper_sensor()
    ses = simulate_calibration(
        sen,
        np.random.default_rng(3),
        n_views=3,
        n_plane_poses=2,
        plane_indices=[10, 60],
    )
    st = ses.plane_stripe_images[1]
    assert isinstance(st, RenderedImages) and len(st) == 2
    first = [st[1], st[0]]
    out: dict[int, np.ndarray] = {}
    threads = [
        threading.Thread(target=lambda j=j: out.__setitem__(j, st[j])) for j in (0, 1)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    np.testing.assert_array_equal(out[0], first[1])
    np.testing.assert_array_equal(out[1], first[0])
    np.testing.assert_array_equal(ses.chessboard_images[2], ses.chessboard_images[-1])
    assert not np.array_equal(st[0], st[1])
    st.release()
    np.testing.assert_array_equal(st[0], first[1])
    with pytest.raises(IndexError):
        st[2]
    # the same session again from the same seed: the same images
    again = simulate_calibration(
        sen,
        np.random.default_rng(3),
        n_views=3,
        n_plane_poses=2,
        plane_indices=[10, 60],
    )
    np.testing.assert_array_equal(again.plane_stripe_images[1][0], first[1])
