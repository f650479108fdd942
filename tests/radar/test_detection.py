"""CA-CFAR and point extraction on synthetic cubes."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.radar import bin_indices, ca_cfar_mask, detect_points, spherical_to_cartesian
from sim2radar.radar.binning import accumulate


def test_cfar_finds_targets_above_clutter_and_ignores_flat_clutter(mmwcas):
    rng = np.random.default_rng(0)
    shape = (mmwcas.n_range_bins, mmwcas.n_azimuth_bins, mmwcas.n_elevation_bins)
    noise = 10 ** (mmwcas.detection.noise_floor_db / 10)
    power = noise * rng.exponential(size=shape)
    power[100, 50, 1] = noise * 1e4  # 40 dB target
    power[150, 20, 0] = noise * 1e3  # 30 dB target
    mask = ca_cfar_mask(power, mmwcas.detection)
    assert mask[100, 50, 1] and mask[150, 20, 0]
    assert mask.sum() <= 4  # noise alone: false alarms stay rare at 8 dB + 10 dB SNR
    # a uniform clutter plateau is not a detection (CFAR adapts), its edge cell may be
    power2 = np.full(shape, noise)
    power2[50:120, 10, 1] = noise * 1e3
    mask2 = ca_cfar_mask(power2, mmwcas.detection.model_copy(update={"peak_grouping": False}))
    assert mask2[60:110, 10, 1].sum() == 0


def test_points_land_at_the_weighted_position(mmwcas):
    rng_m = np.array([3.0, 3.01])
    az = np.radians([10.0, 10.2])
    el = np.zeros(2)
    idx = bin_indices(rng_m, az, el, mmwcas)
    assert idx[0] == idx[1] >= 0
    acc = accumulate(
        idx,
        np.array([1e-2, 1e-2 + 0j]),
        rng_m,
        az,
        el,
        n_cells=mmwcas.n_range_bins * mmwcas.n_azimuth_bins * mmwcas.n_elevation_bins,
    )
    cube = acc.cube((mmwcas.n_range_bins, mmwcas.n_azimuth_bins, mmwcas.n_elevation_bins))
    pts = detect_points(cube, acc, mmwcas)
    assert len(pts) == 1
    expected = spherical_to_cartesian(np.array([3.005]), np.radians([10.1]), np.zeros(1))[0]
    np.testing.assert_allclose(pts[0, :3], expected, atol=1e-4)
    assert pts[0, 3] == pytest.approx(10 * np.log10(4 * np.pi * (2e-2) ** 2), abs=1e-3)


def test_out_of_fov_returns_are_dropped(mmwcas):
    idx = bin_indices(np.array([3.0, 3.0, 20.0]), np.radians([0.0, 80.0, 0.0]), np.zeros(3), mmwcas)
    assert idx[0] >= 0 and idx[1] == -1 and idx[2] == -1
