"""A scan whose images hold no laser stripe (laser off, images of another set-up) gave
"0 points" and exit 0 without a word; the empty cloud then failed in fit-sphere as "no
data rows". It is still written, with a warning that says why it may be empty."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.io import write_image
from kinecal.sensor import paper_sensor
from kinecal.workflows import reconstruct_scan


def test_no_stripe_in_any_image_is_a_warning(tmp_path):
    sensor = paper_sensor()
    cam = sensor.camera
    rng = np.random.default_rng(0)
    for k in (0, 40, 80):  # noise and a dark frame: nothing a stripe detector keeps
        img = rng.integers(0, 256, (cam.height, cam.width)).astype(np.uint8)
        write_image(tmp_path / f"plane_{k:03d}.png", img if k else img * 0)
    with pytest.warns(
        UserWarning, match="no laser stripe found in any of its 3 images"
    ):
        cloud = reconstruct_scan(tmp_path, sensor)
    assert cloud.points.shape == (0, 3)
