"""The signal-level reference radar end to end (sim2radar.radar.signal): point targets are
detected where they are, resolutions are the preset's, SNR follows the radar equation,
Doppler lands in the right bin, and the preset is what the reference radar claims."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from sim2radar.constants import SPEED_OF_LIGHT_M_S
from sim2radar.radar import link_budget, load_radar_config
from sim2radar.radar.paths import PathSet
from sim2radar.radar.signal import POINT_COLUMNS, simulate_signal_frame


@pytest.fixture(scope="module")
def reference():
    return load_radar_config("ti-mmwcas-reference")


@pytest.fixture(scope="module")
def clean(reference):
    """The reference without impairments, leakage, ADC and IF high-pass, with sub-bin
    interpolation (accuracy tests) — TI's chain otherwise."""
    return reference.with_updates(
        hardware={"if_highpass_hz": None},
        signal={"interpolate": True, "adc_bits": None, "tx_rx_leakage_db": None,
                "channel_gain_error_db": 0.0, "channel_phase_error_deg": 0.0,
                "mutual_coupling_db": None})


def point(r_m, az_deg, el_deg=0.0):
    a, e = math.radians(az_deg), math.radians(el_deg)
    return [r_m * math.cos(e) * math.cos(a), r_m * math.cos(e) * math.sin(a), r_m * math.sin(e)]


def spherical(points):
    r = np.linalg.norm(points[:, :3], axis=1)
    return r, np.degrees(np.arctan2(points[:, 1], points[:, 0])), np.degrees(
        np.arcsin(points[:, 2] / r))


def near(points, r_m, az_deg, dr_m, daz_deg):
    r, az, _ = spherical(points)
    return points[(np.abs(r - r_m) <= dr_m) & (np.abs(az - az_deg) <= daz_deg)]


def test_reference_preset_is_the_cascade_at_signal_fidelity(reference):
    base = load_radar_config("ti-mmwcas")
    assert reference.fidelity == "signal" and reference.max_bounces == 3
    for field in ("start_frequency_hz", "bandwidth_hz", "adc_samples", "adc_sample_rate_hz",
                  "n_chirps", "tx_antennas_half_wl", "rx_antennas_half_wl",
                  "chirp_idle_time_s", "adc_start_time_s", "azimuth_fov_deg"):
        assert getattr(reference, field) == getattr(base, field), field
    assert reference.scattering.model == "directive" and reference.scattering.transmission
    assert reference.scattering.lobe_exponent and reference.scattering.slab_thickness_m
    sig = reference.signal
    assert sig.doppler == "full" and sig.synthesis == "narrowband"
    # TI's cascade example (module_param.m): dual-pass CASO on the integrated map, no grouping,
    # 1 dB azimuth peak rule, unwindowed Doppler and angle FFTs, bins without interpolation
    assert (sig.cfar_domain, sig.cfar_kind) == ("range-doppler", "caso")
    assert sig.cfar_training_cells == (8, 4) and sig.cfar_guard_cells == (8, 0)
    assert sig.cfar_threshold == (5.0, 3.0) and sig.cfar_discard_range_bins == (10, 20)
    assert not sig.peak_grouping and sig.angle_sidelobe_db == 1.0 and not sig.interpolate
    assert (sig.range_window, sig.doppler_window, sig.azimuth_window) == ("hanning", "none",
                                                                        "none")
    assert sig.tx_order == tuple(range(11, -1, -1))     # TxToEnable = [12 11 ... 1]


@pytest.mark.parametrize("r_m, az_deg, el_deg", [(4.0, 0.0, 0.0), (2.7, 25.0, 6.0),
                                                 (6.3, -40.0, -4.0), (3.4, 55.0, 0.0)])
def test_point_target_in_its_range_bin_and_azimuth(reference, r_m, az_deg, el_deg):
    """Full reference radar (impairments, leakage, 12-bit ADC, noise; TI's bins): the strongest
    point is in the target's range bin +-1 and within one azimuth resolution (1.18 deg / cos az:
    the beam broadens off boresight); elevation within one elevation FFT bin and the 14.5 deg
    resolution's accuracy."""
    frame = simulate_signal_frame(PathSet.point_targets([point(r_m, az_deg, el_deg)], 1.0),
                                  reference, seed=11)
    best = frame.points[0]
    r, az, el = (v[0] for v in spherical(best[None]))
    assert abs(round(r / reference.range_resolution_m) - round(r_m / reference.range_resolution_m)
               ) <= 1
    res_deg = math.degrees(reference.azimuth_resolution_rad) / math.cos(math.radians(az_deg))
    assert abs(az - az_deg) <= res_deg
    assert abs(el - el_deg) <= 3.0
    assert best[4] == 0.0                                            # static: zero Doppler


def test_one_point_target_has_no_angle_sidelobe_points(reference):
    """A 1 m^2 point target at 4 m (SNR >= 60 dB) through TI's chain: every point lies within
    one azimuth resolution of it — the rectangular azimuth FFT's sidelobes (-13 dB) are far
    below TI's 1 dB peak rule, so no arc. TI's range pass (CASO, 8 guard cells, no peak
    grouping) also reports the target's own Hann range sidelobes while they stand 7 dB over
    the cells 9-16 bins away: those points share its azimuth, sit within 8 range bins and fall
    off by >= 10 dB per bin beyond the main lobe. With peak grouping (the option) the target is
    at most 3 points."""
    target = point(4.0, 10.0)
    frame = simulate_signal_frame(PathSet.point_targets([target], 1.0), reference, seed=1)
    pts = frame.points
    assert pts[0, 3] - frame.stats["noise_floor_db"] >= 60.0
    r, az, _ = spherical(pts)
    assert np.all(np.abs(az - 10.0) <= math.degrees(reference.azimuth_resolution_rad))
    bins = np.round((r - r[0]) / reference.range_resolution_m)
    assert np.all(np.abs(bins) <= 8)
    assert np.all(pts[np.abs(bins) >= 2, 3] < pts[0, 3] - 10.0)
    grouped = simulate_signal_frame(PathSet.point_targets([target], 1.0),
                                    reference.with_updates(signal={"peak_grouping": True}),
                                    seed=1)
    assert 1 <= grouped.n_points <= 3
    _, az_g, _ = spherical(grouped.points)
    assert np.all(np.abs(az_g - 10.0) <= math.degrees(reference.azimuth_resolution_rad))


def test_two_targets_at_one_range_6_deg_apart_one_20_db_weaker(reference):
    """Two targets at 5 m, 6 deg apart, the second 20 dB weaker and moving (its own Doppler
    cell, as walls at different angles are from a moving rig): both are detected, and nothing
    else is in that range bin. In one range-Doppler cell TI's 1 dB azimuth rule keeps only the
    stronger (the weaker is below the -13 dB sidelobes a rule loose enough for it would let
    through) — that is the device chain's behaviour, checked here too."""
    paths = PathSet.point_targets([point(5.0, 0.0), point(5.0, 6.0)], [1.0, 0.01],
                                  range_rate_mps=[0.0, -0.6])
    frame = simulate_signal_frame(paths, reference, seed=2)
    r, az, _ = spherical(frame.points)
    same_bin = np.round(r / reference.range_resolution_m) == round(5.0 /
                                                                  reference.range_resolution_m)
    res = math.degrees(reference.azimuth_resolution_rad)
    found = [np.any(same_bin & (np.abs(az - a) <= res)) for a in (0.0, 6.0)]
    assert all(found), found
    stray = same_bin & (np.abs(az) > res) & (np.abs(az - 6.0) > res)
    assert not stray.any(), frame.points[stray]
    static = simulate_signal_frame(
        PathSet.point_targets([point(5.0, 0.0), point(5.0, 6.0)], [1.0, 0.01]), reference, seed=2)
    r, az, _ = spherical(static.points)
    same_bin = np.round(r / reference.range_resolution_m) == round(5.0 /
                                                                  reference.range_resolution_m)
    assert np.all(np.abs(az[same_bin]) <= res)


def test_left_is_left_and_up_is_up(clean):
    frame = simulate_signal_frame(PathSet.point_targets([[4.0, 1.5, 0.8]]), clean)
    x, y, z = frame.points[0, :3]
    assert x > 3.0 and y == pytest.approx(1.5, abs=0.1) and z == pytest.approx(0.8, abs=0.3)


def test_range_resolution_is_c_over_2b(reference):
    """The range axis steps by c / (2 B) = 0.038 m for B = 3.95 GHz, and targets at ranges from
    1 to 8 m are reported at (bin index) x c/2B within half a bin plus the rounding (TI's
    chain reports bin positions)."""
    frame_axis = simulate_signal_frame(PathSet.point_targets([[3.0, 0, 0]]), reference).range_m
    dr = SPEED_OF_LIGHT_M_S / (2 * reference.bandwidth_hz)
    assert np.diff(frame_axis).mean() == pytest.approx(dr, rel=1e-6)
    assert reference.range_resolution_m == pytest.approx(0.038, abs=5e-4)
    ranges = np.array([1.03, 2.51, 4.24, 6.07, 7.98])
    found = []
    for r in ranges:
        frame = simulate_signal_frame(PathSet.point_targets([[r, 0.0, 0.0]]), reference)
        found.append(np.linalg.norm(frame.points[0, :3]))
    assert np.all(np.abs(np.array(found) - ranges) <= 0.5 * dr + 1e-6)
    assert np.allclose(np.array(found) / dr, np.round(np.array(found) / dr), atol=1e-3)


@pytest.mark.parametrize("separation, resolved", [(2.0, True), (0.5, False)])
def test_two_targets_in_range(clean, separation, resolved):
    """Two equal targets (phases in quadrature, i.e. powers add) separated by 2 range
    resolutions show two peaks, by 0.5 resolution one."""
    dr = clean.range_resolution_m
    paths = PathSet.point_targets([[4.0, 0, 0], [4.0 + separation * dr, 0, 0]],
                                  phase_rad=[0.0, math.pi / 2])
    frame = simulate_signal_frame(paths, clean.with_updates(signal={"peak_grouping": True}))
    pts = near(frame.points, 4.0 + 0.5 * separation * dr, 0.0, 3 * dr, 1.0)
    assert len(pts) == (2 if resolved else 1)


@pytest.mark.parametrize("separation, resolved", [(2.0, True), (0.5, False)])
def test_two_targets_in_azimuth(clean, separation, resolved):
    """Two equal targets at 5 m separated by 2 azimuth resolutions (0.886 lambda / D) show two
    peaks, by 0.5 resolution one."""
    half = 0.5 * separation * math.degrees(clean.azimuth_resolution_rad)
    paths = PathSet.point_targets([point(5.0, -half), point(5.0, half)],
                                  phase_rad=[0.0, math.pi / 2])
    frame = simulate_signal_frame(paths, clean.with_updates(signal={"peak_grouping": True}))
    pts = near(frame.points, 5.0, 0.0, 2 * clean.range_resolution_m, 3 * max(half, 1.0))
    assert len(pts) == (2 if resolved else 1)
    if resolved:
        _, az, _ = spherical(pts)
        assert np.sort(az) == pytest.approx([-half, half], abs=0.5 * half)


def test_detected_snr_falls_as_r_to_the_fourth(clean):
    """A 1 m^2 point target at 3-8 m: SNR (intensity over the reported noise floor) follows
    -40 log10(R) within 1 dB (seeded noise; the array's near-field defocus is < 0.3 dB
    beyond 3 m)."""
    ranges = np.array([3.0, 4.5, 6.0, 8.0])
    snr = []
    for i, r in enumerate(ranges):
        frame = simulate_signal_frame(PathSet.point_targets([[r, 0.0, 0.0]]), clean, seed=i)
        snr.append(frame.points[0, 3] - frame.stats["noise_floor_db"])
    expected = snr[0] - 40 * np.log10(ranges / ranges[0])
    assert np.abs(np.array(snr) - expected).max() < 1.0
    # and the absolute level is the radar equation referred to |a|^2: sigma/r^4 in dB
    assert frame.points[0, 3] == pytest.approx(-40 * math.log10(8.0), abs=0.5)


def test_element_pattern_lowers_off_boresight_intensity(clean):
    """At 45 deg the detected intensity drops by the two-way element pattern (cos^q, 100 deg
    HPBW: 4.7 dB) plus the wideband aperture loss (a target off boresight spans ~1.5 range bins
    across the 86-element aperture): within [pattern, pattern + 1.5 dB]."""
    i0 = simulate_signal_frame(PathSet.point_targets([point(6.0, 0.0)]), clean).points[0, 3]
    i45 = simulate_signal_frame(PathSet.point_targets([point(6.0, 45.0)]), clean).points[0, 3]
    pattern_db = 20 * math.log10(link_budget.element_power_pattern(clean, math.pi / 4, 0.0))
    assert pattern_db - 1.5 <= i45 - i0 <= pattern_db + 0.1


def test_moving_target_in_its_doppler_bin_and_azimuth(clean):
    """Full chirp cube (32 loops): targets receding at +0.9 m/s and approaching at -1.7 m/s are
    reported within one Doppler bin (lambda / (2 N T_loop)) of their speed, with positive =
    receding, at the right azimuth and elevation and with a clean beam: the TDM phase between
    TX slots (up to 2 rad here) is compensated per Doppler bin; without it the elevation is
    off by ~2 deg and a spurious peak 5 dB below the target appears 2.5 deg away. (TI's chain
    reports the target's range and Doppler sidelobes too — at its azimuth.)"""
    radar = clean.with_updates(adc_samples=128, n_chirps=32,
                               signal={"doppler": "full", "cfar_training_cells": (8, 4)})
    t_loop = radar.n_tx * radar.chirp_period_s
    dv = radar.wavelength_m / (2 * radar.n_chirps * t_loop)
    vmax = radar.wavelength_m / (4 * t_loop)
    assert 1.7 < vmax
    paths = PathSet.point_targets([point(2.2, 30.0), point(3.5, -20.0)], [1.0, 1.0],
                                  range_rate_mps=[0.9, -1.7])
    frame = simulate_signal_frame(paths, radar, seed=3)
    for (r, az), v in (((2.2, 30.0), 0.9), ((3.5, -20.0), -1.7)):
        pts = near(frame.points, r, az, 2 * radar.range_resolution_m, 2.0)
        assert len(pts), (r, az)
        best = pts[np.argmax(pts[:, 3])]
        assert best[4] == pytest.approx(v, abs=dv)
        _, az_found, el_found = (x[0] for x in spherical(best[None]))
        assert az_found == pytest.approx(az, abs=0.5)
        assert el_found == pytest.approx(0.0, abs=1.5)
        others = near(frame.points, r, az, 3 * radar.range_resolution_m, 5.0)
        _, az_o, _ = spherical(others)
        ghosts = others[np.abs(az_o - az_found) > math.degrees(radar.azimuth_resolution_rad)]
        assert np.all(ghosts[:, 3] < best[3] - 10.0)   # no TDM ghost beside the target


def test_integrated_and_full_doppler_give_the_same_static_points(clean):
    """Static scene, noise-free: integrated Doppler and the full chirp cube report the same
    points (position within 1 mm, intensity within 0.01 dB)."""
    radar = clean.with_updates(adc_samples=128, n_chirps=16)
    paths = PathSet.point_targets([point(2.0, 15.0), point(3.3, -40.0, 10.0)], [1.0, 0.5])
    a = simulate_signal_frame(paths, radar)
    b = simulate_signal_frame(paths, radar.with_updates(signal={"doppler": "full"}))
    assert len(a.points) == len(b.points) > 0
    assert np.abs(a.points[:, :3] - b.points[:, :3]).max() < 1e-3
    assert np.abs(a.points[:, 3] - b.points[:, 3]).max() < 0.01


@pytest.mark.parametrize("interpolate", [False, True])
def test_points_without_the_heatmap_are_the_same_points(reference, interpolate):
    """The factory's frames skip the range-azimuth heatmap; the azimuth spectra are then taken
    only at the cells the points read: the same points bit for bit, on a noisy frame of a
    walking rig with a few targets."""
    radar = reference.with_updates(signal={"interpolate": interpolate})
    paths = PathSet.point_targets([point(2.5, 20.0), point(4.0, -35.0, 8.0), point(6.0, 3.0)],
                                  [1.0, 0.3, 0.1])
    paths = dataclasses.replace(paths, range_rate_mps=np.array([-0.8, -0.5, -1.0]))
    full = simulate_signal_frame(paths, radar, seed=6)
    lean = simulate_signal_frame(paths, radar, seed=6, heatmap=False)
    assert lean.range_azimuth_db is None and full.range_azimuth_db is not None
    assert len(full.points) >= 3
    assert np.array_equal(full.points, lean.points)


def test_frame_fields_and_determinism(reference):
    paths = PathSet.point_targets([point(3.0, 10.0), point(5.0, -30.0)])
    a = simulate_signal_frame(paths, reference, return_cubes=True)
    b = simulate_signal_frame(paths, reference)
    c = simulate_signal_frame(paths, reference, seed=4)
    d = simulate_signal_frame(paths, reference, seed=4)
    assert a.points.dtype == np.float32 and a.points.shape[1] == len(POINT_COLUMNS) == 5
    assert np.array_equal(a.points, b.points) and np.array_equal(c.points, d.points)
    assert a.range_azimuth_db.shape == (reference.adc_samples, len(a.azimuth_sin))
    assert np.all(np.abs(a.azimuth_sin) <= math.sin(math.radians(60)) + 1e-6)
    assert a.if_samples.shape == (64, 12, 16, 256)
    assert a.range_doppler_cube.shape == (64, 12, 16, 256)
    assert a.range_doppler_db.shape == (256, 64)
    for key in ("seconds_synthesis", "seconds_processing", "seconds_total", "noise_floor_db",
                "n_paths", "n_detections", "cfar_alpha_range_db", "cfar_design_pfa_range"):
        assert key in a.stats
    assert np.all(np.diff(a.points[:, 3]) <= 0)                      # strongest first


@pytest.mark.gpu
def test_gpu_frame_equals_cpu_frame(reference):
    """The torch chain on CUDA gives the CPU's points. Compared noise-free: with a seed the
    GPU draws its noise there, from another stream than the CPU's NumPy one (with noise, both
    still find both targets)."""
    import torch

    paths = PathSet.point_targets([point(3.0, 10.0), point(5.0, -30.0, 5.0)])
    for seed in (2, 3):
        noisy = simulate_signal_frame(paths, reference, seed=seed, device=torch.device("cuda"))
        assert noisy.stats["device"].startswith("cuda")
        for r_m, az_deg in ((3.0, 10.0), (5.0, -30.0)):
            assert len(near(noisy.points, r_m, az_deg, 3 * reference.range_resolution_m, 2.0))
    cpu = simulate_signal_frame(paths, reference, device=torch.device("cpu")).points
    gpu = simulate_signal_frame(paths, reference, device=torch.device("cuda")).points
    assert len(cpu) == len(gpu) > 0
    # Pair each CPU point with a GPU point of the same range and Doppler and the nearest
    # direction (points are sorted by intensity, so near-equal ones may swap places). cuFFT
    # and pocketfft round differently; where two adjacent bins of the zero-padded angle FFTs
    # are within that rounding, the peak moves by one bin (seen on an H100: one point of 52).
    r_c, r_g = (np.linalg.norm(p[:, :3], axis=1) for p in (cpu, gpu))
    u_c, u_g = cpu[:, 1] / r_c, gpu[:, 1] / r_g          # azimuth FFT's axis, sin(az)cos(el)
    w_c, w_g = cpu[:, 2] / r_c, gpu[:, 2] / r_g          # elevation FFT's axis, sin(el)
    same_cell = (np.abs(r_c[:, None] - r_g[None]) < 1e-3) & (
        np.abs(cpu[:, None, 4] - gpu[None, :, 4]) < 1e-4)
    du, dw = np.abs(u_c[:, None] - u_g[None]), np.abs(w_c[:, None] - w_g[None])
    cost = np.where(same_cell, du + dw, 1e3)
    rows, cols = linear_sum_assignment(cost)
    assert np.all(same_cell[rows, cols]), "a CPU point has no GPU point in its range-Doppler cell"
    one_bin = 2.0 / np.array([reference.signal.azimuth_fft_size,
                              reference.signal.elevation_fft_size])
    assert np.all(du[rows, cols] <= one_bin[0] + 1e-4) and np.all(dw[rows, cols] <= one_bin[1] + 1e-4)
    exact = (du[rows, cols] < 1e-4) & (dw[rows, cols] < 1e-4)
    assert exact.mean() >= 0.9, f"{(~exact).sum()} of {len(cpu)} points moved by an angle bin"
    assert np.abs(cpu[rows, 3] - gpu[cols, 3]).max() < 0.01


def test_clutter_removal_drops_what_does_not_move_relative_to_the_radar(clean):
    """TI's optional clutter removal (mean over chirps subtracted): a static target vanishes,
    a moving one stays (full chirp cube)."""
    paths = PathSet.point_targets([point(3.0, 10.0), point(4.5, -20.0)], [1.0, 1.0],
                                  range_rate_mps=[0.0, -0.8])
    radar = clean.with_updates(signal={"doppler_clutter_removal": True})
    frame = simulate_signal_frame(paths, radar, seed=5)
    assert len(near(frame.points, 4.5, -20.0, 3 * radar.range_resolution_m, 2.0))
    assert not len(near(frame.points, 3.0, 10.0, 3 * radar.range_resolution_m, 2.0))
    kept = simulate_signal_frame(paths, clean, seed=5)
    assert len(near(kept.points, 3.0, 10.0, 3 * radar.range_resolution_m, 2.0))
