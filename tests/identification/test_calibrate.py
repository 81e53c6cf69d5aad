"""Helpers of the calibration pipeline."""

from __future__ import annotations

import pytest
from scipy.special import chdtri

from kinecal.identification._calibrate import chi2_isf


@pytest.mark.parametrize("df", [1, 2, 3, 4, 5, 6, 9])
def test_chi2_quantile_matches_scipy(df):
    for p in (0.5, 0.05, 1e-3, 1e-6, 1e-12):
        assert chi2_isf(df, p) == pytest.approx(chdtri(df, p), rel=1e-10)


def test_chi2_quantile_rejects_bad_arguments():
    with pytest.raises(ValueError, match="0 < p < 1"):
        chi2_isf(3, 0.0)
