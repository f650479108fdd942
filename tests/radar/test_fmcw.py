"""IF synthesis (sim2radar.radar.fmcw): geometry, time vs frequency synthesis, Doppler
integration, element patterns, IF filter, impairments, noise and ADC."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from sim2radar.constants import SPEED_OF_LIGHT_M_S
from sim2radar.radar import link_budget, load_radar_config
from sim2radar.radar.fmcw import (
    channel_impairments,
    element_positions_m,
    if_filter_response,
    slot_times_s,
    synthesize_if,
    window_weights,
)
from sim2radar.radar.paths import PathSet

CPU = torch.device("cpu")


@pytest.fixture(scope="module")
def reference():
    return load_radar_config("ti-mmwcas-reference")


def clean(radar, **signal):
    """``radar`` without impairments, leakage, ADC and IF high-pass (unless given), with the
    exact per-channel NUFFT ('frequency'), integrated Doppler, a Hann Doppler window and TDM
    in list order: the synthesis machinery under test here."""
    sig = {"adc_bits": None, "tx_rx_leakage_db": None, "channel_gain_error_db": 0.0,
           "channel_phase_error_deg": 0.0, "mutual_coupling_db": None, "synthesis": "frequency",
           "doppler": "integrated", "doppler_window": "hann", "tx_order": None, **signal}
    return radar.with_updates(hardware={"if_highpass_hz": None}, signal=sig)


@pytest.fixture(scope="module")
def small(reference):
    """A reduced chirp (128 samples, 16 loops; R_max 4.9 m) for full-cube tests."""
    return clean(reference.with_updates(adc_samples=128, n_chirps=16))


def point(r_m, az_deg, el_deg=0.0):
    a, e = math.radians(az_deg), math.radians(el_deg)
    return [r_m * math.cos(e) * math.cos(a), r_m * math.cos(e) * math.sin(a), r_m * math.sin(e)]


def range_spectrum_db(samples, radar):
    """(…, N) windowed range FFT power [dB]."""
    w = window_weights(radar.signal.range_window, samples.shape[-1])
    return 10 * np.log10(np.abs(np.fft.fft(samples * w, axis=-1)) ** 2 + 1e-300)


def test_element_positions_centred_half_wavelength_and_left_positive(reference):
    tx, rx = element_positions_m(reference)
    half = 0.5 * reference.wavelength_m
    virtual = (tx[:, None, :] + rx[None, :, :]).reshape(-1, 3)
    assert np.allclose(virtual.mean(axis=0), 0.0, atol=1e-12)   # origin at the phase centre
    assert np.allclose(tx[:, 0], 0) and np.allclose(rx[:, 0], 0)  # array in the x = 0 plane
    assert rx[1, 1] - rx[0, 1] == pytest.approx(half)          # RX2 one lambda/2 left of RX1
    assert np.all(tx[:3, 2] > tx[3:, 2].max())                 # TX1-3 are the elevated ones
    assert tx[0, 2] - tx[3, 2] == pytest.approx(6 * half)
    # the azimuth row spans 86 positions lambda/2 apart
    row = np.unique(np.round(virtual[np.isclose(virtual[:, 2], virtual[:, 2].min()), 1] / half, 6))
    assert len(row) == 86 and np.allclose(np.diff(row), 1.0)


def test_channel_phases_fall_towards_a_left_target(reference):
    """A target at +azimuth (left) is nearer to elements of larger y: the IF phase
    +2 pi f tau is smaller there (the convention the beamformer is matched to)."""
    radar = clean(reference)
    cube = synthesize_if(PathSet.point_targets([point(5.0, 20.0)]), radar, device=CPU)
    x = cube.samples[0].numpy()                                  # (T, R, N)
    _, rx = element_positions_m(radar)
    # RX1 -> RX2 (lambda/2 further left): phase change -k d sin(20 deg) (far field ~)
    dphi = np.angle(np.sum(x[3, 1] * np.conj(x[3, 0])))
    k = 2 * math.pi / radar.wavelength_m
    expected = -k * (rx[1, 1] - rx[0, 1]) * math.sin(math.radians(20))
    assert dphi == pytest.approx(expected, abs=0.05)


def test_slot_times_follow_tdm_order(reference):
    reference = reference.with_updates(signal={"tx_order": None})
    t = slot_times_s(reference)
    tc = reference.chirp_period_s
    assert t.shape == (reference.n_chirps, reference.n_tx)
    assert np.allclose(np.diff(t[0]), tc)                          # one chirp slot per TX
    assert np.allclose(t[1] - t[0], reference.n_tx * tc)           # one loop per chirp index
    assert abs(t.mean()) < tc                                      # frame centre is t = 0
    rev = reference.with_updates(signal={"tx_order": list(range(reference.n_tx))[::-1]})
    assert np.allclose(slot_times_s(rev)[:, ::-1], t)


@pytest.mark.parametrize("doppler", ["integrated", "full"])
def test_frequency_synthesis_matches_time_synthesis_within_0p1_db(small, doppler):
    """The NUFFT (frequency) synthesis reproduces the per-sample (time) reference: the windowed
    range spectrum at each target's peak bin agrees within 0.1 dB in every channel (and the IF
    samples to 1e-4), for a near, off-axis, elevated and a moving target."""
    paths = PathSet.point_targets(
        [point(1.3, -35.0, 5.0), point(2.71, 10.0, -8.0), point(3.9, 50.0)],
        rcs_m2=[0.3, 1.0, 2.0],
        range_rate_mps=[0.0, 0.7 if doppler == "full" else 0.0, -0.4 if doppler == "full" else 0.0],
        phase_rad=[0.2, 1.0, -2.0],
    )
    out = {}
    for mode in ("time", "frequency"):
        radar = small.with_updates(signal={"synthesis": mode, "doppler": doppler})
        out[mode] = synthesize_if(paths, radar, device=CPU).samples.numpy().astype(np.complex128)
    ref, fast = out["time"], out["frequency"]
    assert np.linalg.norm(fast - ref) / np.linalg.norm(ref) < 1e-4
    spec_ref, spec_fast = range_spectrum_db(ref, small), range_spectrum_db(fast, small)
    bins = np.round(np.linalg.norm(paths.departure_point_m, axis=1)
                    / small.range_resolution_m).astype(int)
    diff = np.abs(spec_fast[..., bins] - spec_ref[..., bins])
    assert diff.max() < 0.1


def test_doppler_integrated_signal_equals_the_full_chirp_cube(small):
    """Static scene: the integrated synthesis equals the Doppler-windowed chirp sum of the
    full cube (the zero-Doppler bin) sample by sample."""
    paths = PathSet.point_targets([point(2.0, 15.0), point(3.3, -40.0, 10.0)], [1.0, 0.5])
    full = synthesize_if(paths, small.with_updates(signal={"doppler": "full"}), device=CPU)
    integ = synthesize_if(paths, small, device=CPU)
    w = window_weights(small.signal.doppler_window, small.n_chirps)
    summed = np.einsum("m,mtrn->trn", w, full.samples.numpy().astype(np.complex128))
    got = integ.samples.numpy()[0]
    assert np.linalg.norm(got - summed) / np.linalg.norm(summed) < 1e-5
    assert integ.doppler_gain == pytest.approx(w.sum())


def test_doppler_integrated_noise_equals_the_full_chirp_cube(small):
    """Noise alone: the integrated cube's noise per sample equals that of the full cube's
    zero-Doppler bin, sigma^2 sum(w^2) with sigma^2 = k T F f_s (within 3 %)."""
    empty = PathSet.point_targets(np.zeros((0, 3)))
    full = synthesize_if(empty, small.with_updates(signal={"doppler": "full"}), seed=1,
                         device=CPU).samples.numpy().astype(np.complex128)
    integ = synthesize_if(empty, small, seed=2, device=CPU)
    w = window_weights(small.signal.doppler_window, small.n_chirps)
    dc_bin = np.einsum("m,mtrn->trn", w, full)
    expected = link_budget.noise_power_w(small) * np.sum(w**2)
    assert integ.noise_power_w == pytest.approx(expected)
    assert np.mean(np.abs(dc_bin) ** 2) == pytest.approx(expected, rel=0.03)
    assert np.mean(np.abs(integ.samples.numpy()) ** 2) == pytest.approx(expected, rel=0.03)
    # and thermal noise per chirp sample is k T F f_s
    assert np.mean(np.abs(full) ** 2) == pytest.approx(link_budget.noise_power_w(small), rel=0.02)


@pytest.mark.parametrize("az_deg, el_deg", [(40.0, 0.0), (0.0, 12.0), (-60.0, -5.0)])
def test_element_patterns_attenuate_off_boresight_targets(reference, az_deg, el_deg):
    """IF power of a target off boresight is the boresight power times the two-way cos^q
    element pattern of the preset (100 deg x 30 deg HPBW), within 0.05 dB."""
    radar = clean(reference)
    power = []
    for a, e in ((0.0, 0.0), (az_deg, el_deg)):
        x = synthesize_if(PathSet.point_targets([point(4.0, a, e)]), radar,
                          device=CPU).samples.numpy()
        power.append(np.mean(np.abs(x) ** 2))
    g = link_budget.element_power_pattern(radar, math.radians(az_deg), math.radians(el_deg))
    assert 10 * math.log10(power[1] / power[0]) == pytest.approx(20 * math.log10(g), abs=0.05)
    # and the preset's pattern is -3 dB one-way at half its beamwidth
    half = math.radians(0.5 * radar.hardware.azimuth_hpbw_deg)
    assert link_budget.element_power_pattern(radar, half, 0.0) == pytest.approx(0.5)


def test_echo_power_follows_the_radar_equation(reference):
    """Boresight point target: |x|^2 per sample = P_t G_t G_r lambda^2 sigma / ((4 pi)^3 r^4)
    times (sum of Doppler weights)^2 (integrated)."""
    radar = clean(reference)
    r, sigma = 3.0, 2.0
    cube = synthesize_if(PathSet.point_targets([[r, 0, 0]], sigma), radar, device=CPU)
    hw = radar.hardware
    p_r = (1e-3 * 10 ** (hw.tx_power_dbm / 10) * 10 ** (hw.tx_gain_dbi / 10)
           * 10 ** (hw.rx_gain_dbi / 10) * radar.wavelength_m**2 * sigma
           / ((4 * math.pi) ** 3 * r**4))
    got = np.mean(np.abs(cube.samples.numpy()) ** 2) / cube.doppler_gain**2
    assert got == pytest.approx(p_r, rel=1e-3)


def test_if_filter_rolls_off_and_returns_beyond_r_max_alias(reference):
    """No path is removed: the anti-alias filter is flat to if_bandwidth_fraction x f_adc, then
    falls as hardware.if_rolloff_db (linear in dB between its points); a return beyond the
    unambiguous range keeps its beat frequency and complex sampling aliases it by f_adc, to
    short range, at the stop-band attenuation."""
    radar = clean(reference)
    hw, f_adc = radar.hardware, radar.adc_sample_rate_hz
    f = np.array([0.5, 0.9, 0.95, 1.0, 1.05, 1.1, 1.5]) * f_adc
    gain_db = 20 * np.log10(np.abs(if_filter_response(radar, f)))
    assert gain_db[:2] == pytest.approx([0.0, 0.0], abs=1e-9)
    assert gain_db[2] == pytest.approx(-20.0) and gain_db[3] == pytest.approx(-40.0)
    assert gain_db[4] == pytest.approx(-50.0) and gain_db[5:] == pytest.approx([-60.0, -60.0])
    assert hw.if_rolloff_db == ((1.0, -40.0), (1.1, -60.0))
    r_max = radar.max_range_m
    paths = PathSet.point_targets([[0.5 * r_max, 0, 0], [r_max + 2.0, 0, 0]])
    cube = synthesize_if(paths, radar, device=CPU)
    assert cube.stats["n_paths_synthesised"] == 2 and cube.stats["n_paths_beyond_if_band"] == 1
    spec = range_spectrum_db(cube.samples.numpy()[0], radar).mean(axis=(0, 1))
    dr = radar.range_resolution_m
    near_bin, alias_bin = round(0.5 * r_max / dr), round(2.0 / dr)   # aliased: R - R_max
    # r^-4 and the stop band: the alias sits at its aliased bin, ~60 dB + 40 log10 below
    drop = spec[near_bin] - spec[alias_bin]
    want = 60.0 + 40 * math.log10((r_max + 2.0) / (0.5 * r_max))
    assert np.argmax(spec[alias_bin - 3:alias_bin + 4]) == 3
    assert drop == pytest.approx(want, abs=1.0)
    f = np.array([1e5, 1e6])
    h = if_filter_response(radar.with_updates(hardware={"if_highpass_hz": 175e3}), f)
    assert np.abs(h) ** 2 == pytest.approx(1 / (1 + (175e3 / f) ** 2))  # first-order high-pass


@pytest.mark.parametrize("doppler", ["integrated", "full"])
def test_narrowband_synthesis_matches_time_synthesis(reference, doppler):
    """The sub-array narrowband synthesis against the per-sample reference, full chirp: per
    channel the energy in the target's range bin +-2 and Doppler bin +-2 agrees within 0.1 dB,
    and the beam at the target, summed over that neighbourhood, within 0.15 dB, for near,
    off-axis, elevated and wide-angle targets, static or moving at <= 0.7 m/s (what it leaves
    out: range migration over the frame, < 0.5 range bin there, and each Doppler rounded to
    1/4 bin, which moves energy between neighbouring Doppler bins but keeps it)."""
    radar = clean(reference, doppler_window="none")
    tx, rx = element_positions_m(radar)
    virtual = tx[:, None, :] + rx[None, :, :]
    k = 2 * math.pi / radar.wavelength_m
    cases = [((1.3, -35.0, 5.0), 0.0), ((2.71, 10.0, -8.0), 0.7), ((3.9, 50.0, 0.0), -0.4),
             ((2.0, 60.0, 0.0), 0.3)]
    for (r, az, el), rate in cases:
        paths = PathSet.point_targets([point(r, az, el)], range_rate_mps=rate if doppler == "full"
                                      else 0.0, phase_rad=0.3)
        spec = {}
        for mode in ("time", "narrowband"):
            x = synthesize_if(paths, radar.with_updates(signal={"synthesis": mode,
                                                                "doppler": doppler}),
                              device=CPU).samples.numpy().astype(np.complex128)
            x = np.fft.fft(x * window_weights("hann", x.shape[-1]), axis=-1)
            spec[mode] = np.fft.fft(x, axis=0)
        power = np.abs(spec["time"]) ** 2
        d, b = np.unravel_index(np.argmax(power.sum(axis=(1, 2))),
                                (power.shape[0], power.shape[-1]))
        band = slice(b - 2, b + 3)
        dop = np.arange(d - 2, d + 3) % power.shape[0]
        e_ref = power[dop][..., band].sum(axis=(0, -1))
        e_nb = (np.abs(spec["narrowband"][dop][..., band]) ** 2).sum(axis=(0, -1))
        assert np.abs(10 * np.log10(e_nb / e_ref)).max() < 0.1, (r, az, el)
        steer = np.exp(1j * k * (virtual @ np.array(point(1.0, az, el))))
        beam = {m: (np.abs((z[dop][..., b] * steer).sum(axis=(1, 2))) ** 2).sum()
                for m, z in spec.items()}
        assert abs(10 * math.log10(beam["narrowband"] / beam["time"])) < 0.15


def test_tx_rx_leakage_tone_power(reference):
    """Leakage at -40 dB re P_t: |x|^2 = P_t 1e-4 per sample (times the Doppler gain^2);
    the 175 kHz IF high-pass suppresses it (beat < 20 kHz) by > 15 dB."""
    radar = clean(reference, tx_rx_leakage_db=-40.0)
    empty = PathSet.point_targets(np.zeros((0, 3)))
    x = synthesize_if(empty, radar, device=CPU)
    p_t = 1e-3 * 10 ** (radar.hardware.tx_power_dbm / 10)
    power = np.mean(np.abs(x.samples.numpy()) ** 2) / x.doppler_gain**2
    assert power == pytest.approx(p_t * 1e-4, rel=1e-4)
    hp = synthesize_if(empty, radar.with_updates(hardware={"if_highpass_hz": 175e3}), device=CPU)
    hp_power = np.mean(np.abs(hp.samples.numpy()) ** 2) / hp.doppler_gain**2
    assert 10 * math.log10(hp_power / power) < -15


def test_impairments_fixed_per_board_with_configured_spread(reference):
    radar = reference.with_updates(signal={"channel_gain_error_db": 1.0,
                                           "channel_phase_error_deg": 10.0,
                                           "mutual_coupling_db": -20.0, "impairment_seed": 3})
    a, b = channel_impairments(radar), channel_impairments(radar)
    assert np.array_equal(a.gain, b.gain)                           # the same board every frame
    other = channel_impairments(radar.with_updates(signal={"impairment_seed": 4}))
    assert not np.allclose(a.gain, other.gain)
    gain_db = 20 * np.log10(np.abs(a.gain))
    phase_deg = np.degrees(np.angle(a.gain))
    assert 0.6 < np.std(gain_db) < 1.5 and 6.0 < np.std(phase_deg) < 15.0
    for c in (a.tx_coupling, a.rx_coupling):
        assert np.allclose(c, c.T)
        off = np.abs(c - np.diag(np.diag(c)))
        assert np.allclose(off[off > 0], 10 ** (-20 / 20))
    # RX1..RX4 are lambda/2 apart: RX1 couples to RX2 only among them
    assert a.rx_coupling[0, 1] != 0 and a.rx_coupling[0, 2] == 0
    # TX elements are >= 1 lambda/2 apart in az *and* el or 4 lambda/2 apart: TX2-TX3 differ
    # by (1, 3) -> no coupling
    assert a.tx_coupling[1, 2] == 0


def test_noise_is_seeded_and_none_means_noise_free(small):
    paths = PathSet.point_targets([[2.0, 0.3, 0.0]])
    a = synthesize_if(paths, small, device=CPU).samples.numpy()
    b = synthesize_if(paths, small, device=CPU).samples.numpy()
    c = synthesize_if(paths, small, seed=5, device=CPU).samples.numpy()
    d = synthesize_if(paths, small, seed=5, device=CPU).samples.numpy()
    e = synthesize_if(paths, small, seed=6, device=CPU).samples.numpy()
    assert np.array_equal(a, b) and np.array_equal(c, d) and not np.array_equal(c, e)
    assert np.mean(np.abs(c - a) ** 2) == pytest.approx(
        link_budget.noise_power_w(small) * np.sum(window_weights("hann", small.n_chirps) ** 2),
        rel=0.05)


def test_adc_quantises_on_its_lsb_grid(small):
    """12-bit ADC, full scale 60 dB above the noise rms per rail: samples sit on the LSB grid
    and the noise power grows by the quantisation noise LSB^2/12 per rail (Widrow)."""
    radar = small.with_updates(signal={"doppler": "full", "adc_bits": 12})
    empty = PathSet.point_targets(np.zeros((0, 3)))
    x = synthesize_if(empty, radar, seed=0, device=CPU).samples.numpy().astype(np.complex128)
    sigma2 = link_budget.noise_power_w(radar)
    lsb = 2 * math.sqrt(sigma2 / 2) * 10 ** (60 / 20) / 2**12
    frac = x.real / lsb - 0.5
    assert np.allclose(frac, np.round(frac), atol=1e-3)
    assert np.mean(np.abs(x) ** 2) == pytest.approx(sigma2 + 2 * lsb**2 / 12, rel=0.02)
    cube = synthesize_if(empty, radar, device=CPU)
    assert cube.noise_power_w == pytest.approx(sigma2 + 2 * lsb**2 / 12)


def test_beat_frequency_sets_the_range_bin(small):
    """A target at range R peaks in range bin R / (c / 2B): beat frequency S tau (SWRA553)."""
    r = 2.5
    x = synthesize_if(PathSet.point_targets([[r, 0, 0]]), small, device=CPU).samples.numpy()
    spec = np.abs(np.fft.fft(x[0] * window_weights("hann", small.adc_samples), axis=-1)).mean(
        axis=(0, 1))
    k = int(np.argmax(spec))
    beat_hz = small.slope_hz_per_s * 2 * r / SPEED_OF_LIGHT_M_S
    assert k == round(beat_hz / small.adc_sample_rate_hz * small.adc_samples)
    assert abs(k * small.range_resolution_m - r) <= small.range_resolution_m


def test_coupling_applied_per_side_is_the_kronecker_coupling():
    """TX then RX coupling as two small products equals the 192 x 192 Kronecker product to
    float32 rounding (1e-6 of the peak)."""
    from sim2radar.radar.fmcw import _couple

    g = torch.Generator().manual_seed(0)
    x = torch.randn(3, 12, 16, 32, dtype=torch.complex64, generator=g)
    ctx = torch.randn(12, 12, dtype=torch.complex64, generator=g)
    crx = torch.randn(16, 16, dtype=torch.complex64, generator=g)
    want = torch.einsum("ab,cd,sbdn->sacn", ctx.to(torch.complex128), crx.to(torch.complex128),
                        x.to(torch.complex128))
    got = _couple(torch, ctx, crx, x).to(torch.complex128)
    assert float((got - want).abs().max() / want.abs().max()) < 1e-6


def test_thermal_noise_on_the_host_keeps_numpys_stream_and_on_a_device_its_power():
    """On the CPU the noise is NumPy's default_rng(seed) stream (the frames of earlier
    releases), added in place to the samples as the complex sum would; drawn on the device (a
    torch stream) it has the same power per sample and independent, zero-mean rails."""
    from sim2radar.radar.fmcw import _add_thermal_noise

    shape, power_w = (4, 12, 16, 256), 2.5e-12
    signal = (np.random.default_rng(1).standard_normal(shape) * 1e-6).astype(np.complex64)
    x = torch.as_tensor(signal.copy())
    assert _add_thermal_noise(torch, x, 7, power_w) is x
    rng = np.random.default_rng(7)
    noise = (rng.standard_normal(shape, dtype=np.float32)
             + 1j * rng.standard_normal(shape, dtype=np.float32)).astype(np.complex64)
    noise *= np.float32(math.sqrt(0.5 * power_w))
    assert x.numpy().tobytes() == (signal + noise).tobytes()
    dev = _add_thermal_noise(torch, torch.zeros(shape, dtype=torch.complex64), 7, power_w,
                             on_device=True).numpy()
    dev = dev.astype(np.complex128)
    n = dev.size  # 196k samples: relative std of the power estimate 1 / sqrt(n) ~ 0.2 %
    assert np.mean(np.abs(dev) ** 2) == pytest.approx(power_w, rel=0.02)
    assert abs(np.mean(dev.real * dev.imag)) < 5 * power_w / math.sqrt(n)
    assert abs(np.mean(dev)) < 5 * math.sqrt(power_w / n)
    again = _add_thermal_noise(torch, torch.zeros(shape, dtype=torch.complex64), 7, power_w,
                               on_device=True).numpy()
    assert again.tobytes() == dev.astype(np.complex64).tobytes()


@pytest.mark.parametrize("seed", range(3))
def test_sparse_grid_equals_a_dense_scatter(seed):
    """The narrowband synthesis's CSR gridding (``Y[key_p + j] += taps[p, j] v[p]``) against
    ``np.add.at``: keys shared by many paths, keys at the first and the last allowed row, rows
    no path reaches; the same sums to float32 rounding (a row adds its paths in key order)."""
    from sim2radar.radar.fmcw import _grid_rows

    rng = np.random.default_rng(seed)
    n_paths, w, n_rows = 500, 7, 300
    key = rng.integers(0, n_rows - w + 1, n_paths)
    key[(key >= 100) & (key < 150)] += 60  # rows 106..149: reached by no path
    key[:40] = 17                        # one crowded key
    key[40], key[41] = 0, n_rows - w     # both ends
    taps = rng.random((n_paths, w)).astype(np.float32)
    v = rng.standard_normal((n_paths, 6)).astype(np.float32)
    want = np.zeros((n_rows, 6), np.float64)
    for j in range(w):
        np.add.at(want, key + j, taps[:, j, None].astype(np.float64) * v)
    got = _grid_rows(torch.as_tensor(v), torch.as_tensor(key), torch.as_tensor(taps), n_rows)
    assert got.shape == (n_rows, 6) and got.dtype == torch.float32
    np.testing.assert_allclose(got.numpy(), want, rtol=0, atol=1e-5)
    reached = np.zeros(n_rows, bool)
    for j in range(w):
        reached[key + j] = True
    assert np.all(got.numpy()[~reached] == 0) and (~reached).any()


def test_element_distances_equal_numpys_norm():
    """Path-end-to-element distances summed coordinate by coordinate: the values of
    ``np.linalg.norm`` over the (P, E, 3) differences, bit for bit."""
    from sim2radar.radar.fmcw import _distances_m

    rng = np.random.default_rng(0)
    points = rng.uniform(-8.0, 8.0, (1000, 3))
    elements = rng.uniform(-0.1, 0.1, (16, 3))
    planar = elements.copy()   # an array in the plane x = 0, one row at z = 0.02 (shared)
    planar[:, 0] = 0.0
    planar[:, 2] = 0.02
    for els in (elements, planar, planar[:1]):
        want = np.linalg.norm(points[:, None, :] - els[None, :, :], axis=2)
        got = _distances_m(points, els)
        assert got.shape == want.shape and np.array_equal(got, want)
