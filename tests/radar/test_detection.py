"""Array response, CA-CFAR and point extraction on synthetic contributions.

The deposit twin (binning.deposit, the NumPy side of the Dr.Jit deposit) is checked against
the exact channel signal ``s(x, z) = sum a e^{j pi (x u_a + z u_e)}``: the fine-grid phase error
is at most pi span / (2 M) = pi / 8 per element (binning.py), so per-element amplitudes agree
to |1 - e^{j pi/8}| = 0.39 of one contribution at worst; the test asserts the documented bound.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.radar import (
    array_geometry,
    bin_indices,
    ca_cfar_mask,
    cell_noise_power,
    deposit,
    detect_points,
    spherical_to_cartesian,
)
from sim2radar.radar.binning import add_receiver_noise, azimuth_map, beamform


def _exact_aperture(range_m, u_az, u_el, amp, radar):
    """s(x, z) per range bin by brute force (positions from the virtual array's centroid)."""
    geom = array_geometry(radar)
    s = np.zeros((radar.n_range_bins, len(geom.z_half_wl), len(geom.x_half_wl)), complex)
    ir = np.floor(np.asarray(range_m) / radar.range_resolution_m + 0.5).astype(int)
    for i, a, ua, ue in zip(ir, amp, u_az, u_el, strict=True):
        s[i] += a * np.exp(1j * np.pi * (geom.x_half_wl[None] * ua + geom.z_half_wl[:, None] * ue))
    return s


def test_fine_grid_channel_signal_matches_the_exact_sum(mmwcas):
    rng = np.random.default_rng(0)
    n = 400
    range_m = rng.uniform(1.0, 8.0, n)
    u_az = rng.uniform(-0.85, 0.85, n)
    u_el = rng.uniform(-0.3, 0.3, n)
    amp = rng.normal(size=n) + 1j * rng.normal(size=n)
    geom = array_geometry(mmwcas)
    got = deposit(range_m, u_az, u_el, amp, mmwcas).aperture(geom)
    exact = _exact_aperture(range_m, u_az, u_el, amp, mmwcas)
    # per element: each contribution's phase error <= pi |x| / M (x from the centroid)
    bound = np.zeros_like(exact, dtype=float)
    ir = np.floor(range_m / mmwcas.range_resolution_m + 0.5).astype(int)
    err_phase = np.pi * np.abs(geom.x_half_wl) / geom.fine_az
    for i, a in zip(ir, amp, strict=True):
        bound[i] += np.abs(a) * 2 * np.sin(err_phase / 2)[None, :]
    assert np.all(np.abs(got - exact) <= bound + 1e-9)
    assert err_phase.max() <= np.pi / 8 + 1e-12
    # the FFT evaluates the direct sum over the fine grid, s(x) = sum_g G[g] e^{j pi n u_g}
    acc = deposit(range_m, u_az, u_el, amp, mmwcas)
    n = geom.x_half_wl + geom.x_shift
    direct = np.einsum("zrg,gx->rzx", acc.grid, np.exp(1j * np.pi * np.outer(geom.fine_u, n)))
    np.testing.assert_allclose(acc.aperture(geom), direct, atol=1e-9)


def test_one_scatterer_reads_its_amplitude_in_its_own_beam(mmwcas):
    geom = array_geometry(mmwcas)
    ua, ue = geom.u_az[50], geom.u_el[2]
    acc = deposit(np.array([4.0]), np.array([ua]), np.array([ue]), np.array([0.02 + 0.01j]),
                  mmwcas)
    cube = beamform(acc.aperture(geom), geom)
    ir = round(4.0 / mmwcas.range_resolution_m)
    assert cube[ir, 50, 2] == pytest.approx(0.02 + 0.01j, rel=1e-2)  # fine-grid phase error
    assert np.abs(cube[ir]).max() == pytest.approx(abs(cube[ir, 50, 2]))
    amap = azimuth_map(acc.aperture(geom), geom)
    assert abs(amap[ir, 50]) == pytest.approx(abs(0.02 + 0.01j), rel=1e-2)


def test_cfar_finds_targets_above_clutter_and_ignores_flat_clutter(mmwcas):
    rng = np.random.default_rng(0)
    shape = (mmwcas.n_range_bins, mmwcas.n_azimuth_bins, mmwcas.n_elevation_bins)
    noise = cell_noise_power(mmwcas)
    cfg = mmwcas.detection.model_copy(update={"sidelobe_level_db": None})
    power = noise * rng.exponential(size=shape)
    power[100, 50, 1] = noise * 1e4  # 40 dB target
    power[150, 20, 0] = noise * 1e3  # 30 dB target
    mask = ca_cfar_mask(power, cfg, noise)
    assert mask[100, 50, 1] and mask[150, 20, 0]
    assert mask.sum() <= 4  # noise alone: false alarms stay rare at 8 dB + 10 dB SNR
    # a uniform clutter plateau is not a detection (CFAR adapts), its edge cell may be
    power2 = np.full(shape, noise)
    power2[50:120, 10, 1] = noise * 1e3
    mask2 = ca_cfar_mask(power2, cfg.model_copy(update={"peak_grouping": False}), noise)
    assert mask2[60:110, 10, 1].sum() == 0
    with pytest.raises(ValueError, match="noise_power"):
        ca_cfar_mask(power, cfg)  # derived floor: the caller must pass it


def test_sidelobe_rule_drops_weak_peaks_of_a_strong_range_bin(mmwcas):
    noise = cell_noise_power(mmwcas)
    power = np.full((mmwcas.n_range_bins, mmwcas.n_azimuth_bins), noise)
    power[100, 40] = noise * 1e8  # 80 dB
    power[100, 60] = noise * 1e5  # 30 dB below it in the same range bin: a sidelobe
    power[100, 20] = noise * 1e7  # 10 dB below: kept
    mask = ca_cfar_mask(power, mmwcas.detection, noise)
    assert mask[100, 40] and mask[100, 20] and not mask[100, 60]
    off = mmwcas.detection.model_copy(update={"sidelobe_level_db": None})
    assert ca_cfar_mask(power, off, noise)[100, 60]


def test_point_between_two_beams_is_placed_and_read_at_its_peak(mmwcas):
    """A scatterer half a beam off the grid: the refined peak sits at its true direction and
    reads its full amplitude (no scalloping loss), while the best beam alone is ~3 dB low."""
    geom = array_geometry(mmwcas)
    ua = 0.5 * (geom.u_az[47] + geom.u_az[48])
    ue = 0.05
    r_m = 3.0 + 0.3 * mmwcas.range_resolution_m
    a = np.array([3e-3 + 0j])
    acc = deposit(np.array([r_m]), np.array([ua]), np.array([ue]), a, mmwcas)
    pts = detect_points(None, acc, mmwcas)
    assert len(pts) == 1
    expected = spherical_to_cartesian(np.array([r_m]), np.array([math.asin(ua / math.cos(
        math.asin(ue)))]), np.array([math.asin(ue)]))[0]
    np.testing.assert_allclose(pts[0, :3], expected, atol=2e-3)
    assert pts[0, 3] == pytest.approx(10 * np.log10(4 * np.pi * abs(a[0]) ** 2), abs=0.1)
    beam = np.abs(azimuth_map(acc.aperture(geom), geom)).max() ** 2
    assert 10 * np.log10(beam / abs(a[0]) ** 2) < -2.0


def test_two_unresolved_scatterers_merge_and_resolved_ones_do_not(mmwcas):
    geom = array_geometry(mmwcas)
    rayleigh = 2.0 / (geom.x_half_wl.max() - geom.x_half_wl.min() + 1)
    for sep, expected in ((0.7 * rayleigh, 1), (2.0 * rayleigh, 2)):
        ua = np.array([-sep / 2, sep / 2])
        acc = deposit(np.full(2, 3.0), ua, np.zeros(2), np.full(2, 3e-3 + 0j), mmwcas)
        pts = detect_points(None, acc, mmwcas)
        assert len(pts) == expected, sep
        if expected == 1:
            assert abs(pts[0, 1] / np.linalg.norm(pts[0, :3])) < 0.1 * rayleigh


def test_beam_noise_follows_the_channels_used(mmwcas):
    """Channel noise N N0 per position: beams over n positions carry N N0 / n."""
    geom = array_geometry(mmwcas)
    n0 = 1e-12
    aperture = np.zeros((mmwcas.n_range_bins, len(geom.z_half_wl), len(geom.x_half_wl)),
                        complex)
    noisy = add_receiver_noise(aperture, geom, n0, np.random.default_rng(1))
    assert np.all(noisy[:, ~geom.present] == 0)
    cube = np.abs(beamform(noisy, geom).astype(complex)) ** 2
    amap = np.abs(azimuth_map(noisy, geom).astype(complex)) ** 2
    assert cube.mean() / (n0 * geom.noise_factor) == pytest.approx(1.0, rel=0.05)
    assert amap.mean() / (n0 * geom.main_noise_factor) == pytest.approx(1.0, rel=0.05)
    assert geom.noise_factor == pytest.approx(192 / 134)
    assert geom.main_noise_factor == pytest.approx(192 / 86)


def test_out_of_fov_returns_are_dropped(mmwcas):
    idx = bin_indices(np.array([3.0, 3.0, 20.0]), np.array([0.0, math.sin(math.radians(80)),
                                                           0.0]), np.zeros(3), mmwcas)
    assert idx[0] >= 0 and idx[1] == -1 and idx[2] == -1
