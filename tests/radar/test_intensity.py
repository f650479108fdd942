"""Log-space histogram matching: matched sim intensities follow the real distribution."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.radar.intensity import IntensityMatch, fit_intensity_match


def test_matched_quantiles_agree_with_the_target_distribution():
    rng = np.random.default_rng(0)
    sim = rng.normal(-60.0, 4.0, 20_000)            # narrow, offset sim intensities [dB]
    real = rng.gumbel(-45.0, 7.0, 30_000)           # wider, skewed real intensities [dB]
    match = fit_intensity_match(sim, real)
    out = match.apply(rng.normal(-60.0, 4.0, 20_000))  # fresh sim frames, same distribution
    q = np.linspace(0.05, 0.95, 19)
    # matched quantiles agree with the real ones within 0.3 dB (sampling error ~0.1 dB)
    np.testing.assert_allclose(np.quantile(out, q), np.quantile(real, q), atol=0.3)
    # unmatched quantiles are far off: the test can fail
    assert np.max(np.abs(np.quantile(sim, q) - np.quantile(real, q))) > 5.0


def test_the_map_is_monotone_and_clamps_to_the_target_range():
    rng = np.random.default_rng(1)
    match = fit_intensity_match(rng.normal(0, 1, 1000), rng.normal(10, 3, 1000), n_quantiles=64)
    x = np.linspace(-10, 10, 501)
    y = match.apply(x)
    assert np.all(np.diff(y) >= -1e-6)
    assert y.min() >= match.target_quantiles_db[0] - 1e-6
    assert y.max() <= match.target_quantiles_db[-1] + 1e-6


def test_round_trip_through_dict_and_bad_input():
    rng = np.random.default_rng(2)
    m = fit_intensity_match(rng.normal(0, 1, 100), rng.normal(5, 1, 100))
    m2 = IntensityMatch.from_dict(m.to_dict())
    x = rng.normal(0, 1, 50)
    np.testing.assert_array_equal(m.apply(x), m2.apply(x))
    with pytest.raises(ValueError, match="no source"):
        fit_intensity_match([], [1.0])
    with pytest.raises(ValueError, match="NaN"):
        fit_intensity_match([1.0, np.nan], [1.0])
