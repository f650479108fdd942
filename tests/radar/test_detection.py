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
from sim2radar.radar.detection import detect_frame, doppler_bins


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
    cfg = mmwcas.detection.model_copy(update={"sidelobe_level_db": 20.0})
    mask = ca_cfar_mask(power, cfg, noise)
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


def _haze(n=6000, seed=0):
    """A diffuse multipath field: many weak random-phase contributions over every azimuth and
    the whole range axis, power falling as 1 / r^2 (second-bounce diffuse returns)."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.5, 9.0, n)
    ua = rng.uniform(-0.85, 0.85, n)
    ue = rng.uniform(-0.3, 0.3, n)
    amp = 1e-4 / r * np.exp(2j * np.pi * rng.uniform(size=n))
    return r, ua, ue, amp


def test_integrated_detector_ignores_a_diffuse_multipath_field_the_per_beam_cfar_detects(mmwcas):
    """A weak field spread over all azimuths and ranges (no surface in it) is compared, after
    integrating the channels, with everything its range bins hold: TI's chain finds (almost)
    no range bin standing out, while a CFAR per azimuth beam adapts to the field and detects
    its speckle peaks at its false-alarm rate in beam after beam (the haze of points)."""
    r, ua, ue, amp = _haze()
    acc = deposit(r, ua, ue, amp, mmwcas)
    per_beam = mmwcas.with_updates(detection={"domain": "range-azimuth", "cfar_kind": "ca",
                                              "cfar_guard_cells": 2, "cfar_threshold_db": 8.0,
                                              "sidelobe_level_db": 20.0})
    haze_beam = detect_points(None, acc, per_beam)
    haze_int = detect_points(None, acc, mmwcas)
    assert len(haze_beam) >= 30
    assert len(haze_int) <= 0.1 * len(haze_beam)
    # a surface in the field (a strong return at 3 m) is found
    amp2 = np.append(amp, 3e-3 + 0j)
    pts = detect_points(None, deposit(np.append(r, 3.0), np.append(ua, 0.2), np.append(ue, 0.0),
                                      amp2, mmwcas), mmwcas)
    near = pts[np.abs(np.linalg.norm(pts[:, :3], axis=1) - 3.0) < 2 * mmwcas.range_resolution_m]
    assert len(near) >= 1
    assert abs(near[0, 1] / np.linalg.norm(near[0, :3]) - 0.2) < 0.01


def test_doppler_bins_follow_the_rigs_motion(mmwcas):
    """A rig walking forward at v: a static scatterer at azimuth u has range rate
    -v sqrt(1 - u^2); mirror azimuths share a bin, boresight is the most negative."""
    geom = array_geometry(mmwcas)
    assert not doppler_bins(mmwcas, None).any() and not doppler_bins(mmwcas, np.zeros(3)).any()
    v = 1.0
    bins = doppler_bins(mmwcas, np.array([v, 0.0, 0.0]))
    res = mmwcas.range_rate_resolution_mps
    assert res == pytest.approx(mmwcas.wavelength_m / (2 * 64 * 12 * mmwcas.chirp_period_s))
    u = geom.fine_u
    want = np.floor(-v * np.sqrt(1 - u**2) / res + 0.5)
    np.testing.assert_array_equal(bins, want)
    g0 = int(np.argmin(np.abs(u)))
    assert bins[g0] == bins.min() == round(-v / res)
    inner = np.abs(u) < 0.99
    mirror = np.argmin(np.abs(u[inner][:, None] + u[None, :]), axis=1)
    assert np.all(np.abs(bins[inner] - bins[mirror]) <= 1)


def test_the_range_doppler_profile_sums_the_arrays_channels_only(mmwcas):
    """TI's detection matrix sums |s|^2 over the virtual channels. A scatterer at boresight
    gives every position the same |s| = |a|, so its range bin's profile is n |a|^2 for the
    n = 134 positions holding an element — not 344 |a|^2 over every (x, z) of the 4 x 86 grid,
    which would put the target 4.1 dB above the noise it is compared with (the noise is on the
    134 channels only). A signal on the empty positions alone gives nothing."""
    from sim2radar.radar.detection import channel_profile

    geom = array_geometry(mmwcas)
    n = int(geom.present.sum())
    assert n == 134 and geom.present.size == 344
    a = 2e-3
    acc = deposit(np.array([4.0]), np.zeros(1), np.zeros(1), np.array([a + 0j]), mmwcas)
    ap = acc.aperture(geom)
    ir = int(np.argmax(np.abs(ap).sum(axis=(1, 2))))
    assert channel_profile(ap, geom)[ir] == pytest.approx(n * a**2, rel=1e-3)
    phantom = np.where(geom.present, 0.0, 1.0)[None] * np.ones((3, 1, 1), complex)
    assert np.all(channel_profile(phantom, geom) == 0)


def test_slab_apertures_are_the_aperture_of_each_slabs_points(mmwcas):
    """One product per Doppler slab (Accumulator.slab_apertures) gives the channel signal the
    FFT of Accumulator.aperture gives for that slab's fine points alone (complex64 rounding:
    1e-6 of the strongest), and the slabs add up to the whole aperture."""
    geom = array_geometry(mmwcas)
    rng = np.random.default_rng(4)
    n = 300
    amp = (rng.standard_normal(n) + 1j * rng.standard_normal(n)) * 1e-3
    acc = deposit(rng.uniform(1, 9, n), rng.uniform(-0.9, 0.9, n), rng.uniform(-0.2, 0.2, n),
                  amp, mmwcas)
    bins = doppler_bins(mmwcas, np.array([1.1, 0.2, 0.0]))
    slabs, ap = acc.slab_apertures(geom, bins)
    np.testing.assert_array_equal(slabs, np.unique(bins))
    scale = np.abs(acc.aperture(geom)).max()
    for k, d in enumerate(slabs):
        np.testing.assert_allclose(ap[k], acc.aperture(geom, bins == d), rtol=0,
                                   atol=1e-6 * scale)
    np.testing.assert_allclose(ap.sum(axis=0), acc.aperture(geom), rtol=0, atol=1e-6 * scale)
    one, whole = acc.slab_apertures(geom, np.zeros_like(bins))
    assert one.tolist() == [0] and np.array_equal(whole[0], acc.aperture(geom))


def test_a_moving_rig_separates_returns_that_a_rig_at_rest_merges(mmwcas):
    """Three scatterers at one range, far apart in azimuth: 0, -0.5 and -8 dB. At rest they
    share one range-Doppler cell and TI's 1 dB rule keeps the two strongest; on a walking rig
    their Doppler bins differ (by direction; here by >= 5 bins, beyond the Doppler CFAR's
    4 reference cells, which would mask the weak one next to a strong one, as TI's does) and
    each is found in its own cell."""
    assert mmwcas.detection.domain == "integrated"
    assert mmwcas.detection.sidelobe_level_db == pytest.approx(1.0)
    ua = np.array([-0.6, 0.0, 0.8])
    amp = 3e-3 * 10 ** (np.array([0.0, -0.5, -8.0]) / 20) + 0j
    acc = deposit(np.full(3, 4.0), ua, np.zeros(3), amp, mmwcas)

    def found(velocity):
        pts = detect_frame(acc, mmwcas, velocity_mps=velocity).points
        return np.sort(pts[:, 1] / np.linalg.norm(pts[:, :3], axis=1))

    assert found(None) == pytest.approx([-0.6, 0.0], abs=0.01)
    walking = detect_frame(acc, mmwcas, velocity_mps=np.array([1.2, 0.0, 0.0]))
    u = walking.points[:, 1] / np.linalg.norm(walking.points[:, :3], axis=1)
    assert np.sort(u) == pytest.approx([-0.6, 0.0, 0.8], abs=0.01)
    # each point carries its cell's range rate: -v cos(azimuth), within one bin
    res = mmwcas.range_rate_resolution_mps
    want = -1.2 * np.sqrt(1 - u**2)
    assert np.all(np.abs(walking.doppler_mps - want) <= res)


def test_integrated_detector_with_receiver_noise(mmwcas):
    """With receiver noise in the channels (noise_added) a 40 dB target is found at its range
    and, on noise alone, the CFAR's false alarms stay rare."""
    geom = array_geometry(mmwcas)
    n0 = cell_noise_power(mmwcas)
    rng = np.random.default_rng(3)
    amp = np.array([math.sqrt(1e4 * n0) + 0j])
    acc = deposit(np.array([5.0]), np.array([-0.3]), np.zeros(1), amp, mmwcas)
    noisy = add_receiver_noise(acc.aperture(geom), geom, n0, rng)
    pts = detect_points(None, acc, mmwcas, aperture=noisy, noise_added=True)
    assert len(pts) >= 1
    assert np.linalg.norm(pts[0, :3]) == pytest.approx(5.0, abs=mmwcas.range_resolution_m)
    empty = deposit(np.array([5.0]), np.zeros(1), np.zeros(1), np.zeros(1, complex), mmwcas)
    only_noise = add_receiver_noise(empty.aperture(geom), geom, n0, rng)
    assert len(detect_points(None, empty, mmwcas, aperture=only_noise, noise_added=True)) <= 3


def test_detection_domain_and_cfar_kind_are_checked(mmwcas):
    with pytest.raises(ValueError, match="needs domain 'integrated'"):
        mmwcas.with_updates(detection={"domain": "range-azimuth", "cfar_kind": "caso"})
    with pytest.raises(ValueError, match="cfar_discard_range_bins"):
        mmwcas.with_updates(detection={"cfar_discard_range_bins": [-1, 0]})


@pytest.mark.parametrize("snr", [0.0, 0.05, 1.0])
def test_the_integrated_noise_drawn_in_two_steps_is_the_full_draw(snr):
    """The detector draws a row's receiver noise in two steps: the channel-integrated power
    (three numbers per row, binning.integrated_power), then the whole noise of the rows it
    looks at (binning.row_noise). Against C = 134 independent CN(0, var) samples per row:
    the power is the non-central chi-square with 2C degrees of freedom (scipy), the same
    distribution as the full draw's (two-sample KS); the completed noise adds up to the drawn
    power, and its channels are uncorrelated with variance var and no mean."""
    from scipy import stats

    from sim2radar.radar.binning import integrated_power, row_noise

    c, var, n = 134, 2.0, 4000
    rng = np.random.default_rng(11)
    s = rng.standard_normal(c) + 1j * rng.standard_normal(c)
    s *= math.sqrt(snr * c * var) / max(np.linalg.norm(s), 1e-300)        # |s|^2 = snr C var
    power, drawn = integrated_power(np.full(n, np.sum(np.abs(s) ** 2)), c, var, rng)
    full = rng.standard_normal((n, c)) + 1j * rng.standard_normal((n, c))
    full_power = np.sum(np.abs(s + full * math.sqrt(var / 2)) ** 2, axis=1)
    scaled = power / (var / 2)
    nc = 2 * np.sum(np.abs(s) ** 2) / var
    law = stats.ncx2(2 * c, nc) if nc > 0 else stats.chi2(2 * c)
    assert stats.kstest(scaled, law.cdf).pvalue > 1e-3
    assert stats.ks_2samp(power, full_power).pvalue > 1e-3

    noise = row_noise(np.tile(s, (n, 1)), drawn, rng)
    assert np.allclose(np.sum(np.abs(s + noise) ** 2, axis=1), power, rtol=1e-9)
    per_channel = np.mean(np.abs(noise) ** 2, axis=0)
    assert np.mean(per_channel) == pytest.approx(var, rel=0.02)
    assert np.all(np.abs(per_channel / var - 1) < 0.15)            # 4000 samples: +-4.5 sigma
    assert np.all(np.abs(noise.mean(axis=0)) < 5 * math.sqrt(var / n))
    cov = noise.T @ noise.conj() / n                                 # E n n^H: var I
    assert np.max(np.abs(cov - var * np.eye(c))) < 6 * var / math.sqrt(n)
    assert np.max(np.abs(noise.T @ noise / n)) < 6 * var / math.sqrt(n)  # circular: E n n^T = 0
