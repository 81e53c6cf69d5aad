"""The vectorised chain: shifted sines and cosines for a nearby configuration."""

from __future__ import annotations

import numpy as np
import pytest

from kinecal.models import chain_frames
from kinecal.models._chain import shifted_trig, shifted_trig_if_small
from kinecal.robot import load_robot


def test_shifted_trig_is_exact_to_rounding_for_small_steps(rng):
    theta = rng.uniform(-4.0, 4.0, 20000)
    delta = rng.uniform(-1e-2, 1e-2, 20000)  # the whole range the series is used for
    c, s = shifted_trig(np.cos(theta), np.sin(theta), delta)
    # exact values from the angle sums of exactly rounded cos/sin of delta
    c_ref = np.cos(theta) * np.cos(delta) - np.sin(theta) * np.sin(delta)
    s_ref = np.sin(theta) * np.cos(delta) + np.cos(theta) * np.sin(delta)
    assert np.abs(c - c_ref).max() < 4e-16
    assert np.abs(s - s_ref).max() < 4e-16


@pytest.mark.parametrize("step", [1e-4, 5e-3, 0.3])
def test_chain_near_a_configuration_equals_the_direct_chain(step, rng):
    """Small steps use the shifted trig, a large one the angles themselves: both give the
    frames of the direct evaluation."""
    ch = load_robot("fanuc-lrmate200id").dh_chain()
    theta = rng.uniform(-2.5, 2.5, (500, 6)) + ch.theta_offset
    delta = rng.uniform(-step, step, (6, 500))
    ref = chain_frames(theta, ch.d, ch.a, ch.alpha)
    shifted = shifted_trig_if_small(ref.cos, ref.sin, delta)
    assert (shifted is None) == (step > 0.01)
    near = chain_frames(theta + delta.T, ch.d, ch.a, ch.alpha, trig=shifted)
    direct = chain_frames(theta + delta.T, ch.d, ch.a, ch.alpha)
    np.testing.assert_allclose(near.cos, direct.cos, rtol=0, atol=1e-15)
    np.testing.assert_allclose(near.sin, direct.sin, rtol=0, atol=1e-15)
    np.testing.assert_allclose(near.cols, direct.cols, rtol=0, atol=1e-14)
    np.testing.assert_allclose(near.origin, direct.origin, rtol=0, atol=1e-14)
    assert not np.allclose(near.origin, ref.origin, rtol=0, atol=1e-9)
