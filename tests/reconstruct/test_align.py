"""Tests for sim2radar.reconstruct.align (paper eq. 1, robust)."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.reconstruct.align import align_scale_shift, fit_scale_shift


def _scene(n=400, outlier_frac=0.0, seed=1):
    """Mono depth in arbitrary units and LiDAR depth = 2.5 * mono + 0.4 m (+1 cm noise)."""
    rng = np.random.default_rng(seed)
    mono = rng.uniform(0.3, 3.0, n)
    lidar = 2.5 * mono + 0.4 + rng.normal(0, 0.01, n)
    n_out = int(round(outlier_frac * n))
    idx = rng.choice(n, n_out, replace=False)
    # Gross outliers: returns from far behind (parallax / glass), 2-8 m too far.
    lidar[idx] += rng.uniform(2.0, 8.0, n_out)
    return mono, lidar


def test_exact_recovery_without_outliers():
    mono, lidar = _scene()
    s, t = align_scale_shift(mono, lidar)
    assert s == pytest.approx(2.5, abs=0.01)
    assert t == pytest.approx(0.4, abs=0.02)


def test_twenty_percent_outliers_robust_vs_lsq():
    mono, lidar = _scene(outlier_frac=0.2)
    robust = fit_scale_shift(mono, lidar)
    plain = fit_scale_shift(mono, lidar, method="lsq")
    # Robust estimate stays within 1 % scale / 3 cm shift of the truth ...
    assert robust.scale == pytest.approx(2.5, rel=0.01)
    assert robust.shift_m == pytest.approx(0.4, abs=0.03)
    assert 0.75 * 400 <= robust.n_inliers <= 0.85 * 400
    # ... while plain least squares (eq. 1 as written) is pulled off by > 0.5 m at 2 m depth.
    err_plain = abs(plain.scale * 0.8 + plain.shift_m - (2.5 * 0.8 + 0.4))
    assert err_plain > 0.5


def test_image_inputs_with_mask_and_zero_holes():
    rng = np.random.default_rng(3)
    mono = rng.uniform(1, 2, (20, 30)).astype(np.float32)
    lidar = np.zeros_like(mono)
    sel = rng.random(mono.shape) < 0.2
    lidar[sel] = 0.5 * mono[sel] + 1.0
    lidar[0, :] = 99.0  # masked out below
    mask = np.ones(mono.shape, bool)
    mask[0, :] = False
    s, t = align_scale_shift(mono, lidar, mask, method="lsq")
    assert s == pytest.approx(0.5, abs=1e-4) and t == pytest.approx(1.0, abs=1e-4)


def test_errors_are_clear():
    with pytest.raises(ValueError, match="at least"):
        align_scale_shift(np.ones(5), np.zeros(5))
    with pytest.raises(ValueError, match="shape"):
        align_scale_shift(np.ones(5), np.ones(6))
    with pytest.raises(ValueError, match="method"):
        align_scale_shift(np.ones(5), np.ones(5), method="magic")
