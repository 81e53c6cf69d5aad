"""The stripe benchmarks' helpers (benchmarks/_stripes.py; the benchmarks themselves
run with ``python -m benchmarks --stripes``, not as tests)."""

from __future__ import annotations

import numpy as np
from benchmarks import _stripes

from kinecal.sensor import StripeSpec, score_centres, synthetic_stripe


def test_plain_centroid_baseline_and_the_cases():
    spec = StripeSpec(angle_deg=10.0, read_noise=1.0)
    img = synthetic_stripe(spec, np.random.default_rng(9))
    uv = _stripes.plain_centroid(img)
    s = score_centres(uv, spec.truth(), shape=spec.shape, margin_px=8)
    assert s.coverage > 0.99 and s.rms_px < 0.1  # a clean stripe: a centroid is fine
    names = [n for n, _ in _stripes.synthetic_cases()]
    assert len(names) == len(set(names)) >= 15
    # held-out: none of the tests' seeds (0..1022)
    assert _stripes.SEED > 10_000


def test_turned_planes_make_stripes_of_another_direction():
    from kinecal.sensor import paper_sensor

    planes = paper_sensor().planes
    turned = _stripes._turned(planes, 90.0)
    # the mirror axis (along y) turns to x: the planes' normals lose their x part
    assert np.allclose(np.abs(turned.n[:, 1]), np.abs(planes.n[:, 0]))
    assert np.allclose(turned.b, planes.b)
    assert turned.source is not None and planes.source is not None
    assert np.allclose(turned.source[[1, 0]] * [1, -1], planes.source[:2] * [1, 1])
