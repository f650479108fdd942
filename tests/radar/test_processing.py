"""The processing chain (sim2radar.radar.processing): CFAR design and false-alarm rates,
virtual-array formation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from sim2radar.radar import load_radar_config
from sim2radar.radar.paths import PathSet
from sim2radar.radar.processing import (
    azimuth_row,
    cfar_detect,
    cfar_threshold_factor,
    effective_training_cells,
    effective_training_cells_os,
    training_offsets,
)
from sim2radar.radar.signal import simulate_signal_frame

EMPTY = PathSet.point_targets(np.zeros((0, 3)))


@pytest.fixture(scope="module")
def reference():
    return load_radar_config("ti-mmwcas-reference")


@pytest.mark.parametrize("n", [8, 16, 248])
@pytest.mark.parametrize("pfa", [1e-3, 1e-6])
def test_ca_threshold_is_richards_closed_form(n, pfa):
    """Single look: alpha = N (P_fa^(-1/N) - 1) (Richards §6.5)."""
    assert cfar_threshold_factor("ca", n, pfa) == pytest.approx(n * (pfa ** (-1 / n) - 1),
                                                                rel=1e-6)


@pytest.mark.parametrize("n, rank", [(16, 0.75), (24, 0.5), (248, 0.75)])
def test_os_threshold_is_rohlings(n, rank):
    """Single look: P_fa = prod_{i<k} (N - i) / (N - i + alpha) (Rohling 1983) at the design
    value."""
    pfa = 1e-4
    alpha = cfar_threshold_factor("os", n, pfa, rank=rank)
    k = math.ceil(rank * n)
    got = np.prod([(n - i) / (n - i + alpha) for i in range(k)])
    assert got == pytest.approx(pfa, rel=1e-5)


@pytest.mark.parametrize("kind", ["ca", "os"])
def test_multi_look_threshold_by_monte_carlo(kind):
    """K = 4 non-coherent looks, N = 16 cells: the false-alarm rate of Gamma(4) cells at the
    designed alpha is the design value (2e5 draws, within 10 %)."""
    n, looks, pfa = 16, 4, 1e-2
    alpha = cfar_threshold_factor(kind, n, pfa, looks=looks, rank=0.75)
    rng = np.random.default_rng(0)
    train = rng.gamma(looks, size=(200_000, n))
    cut = rng.gamma(looks, size=200_000)
    ref = train.mean(axis=1) if kind == "ca" else np.sort(train, axis=1)[:, 11]
    assert np.mean(cut > alpha * ref) == pytest.approx(pfa, rel=0.1)


def test_training_window_and_white_cells_are_independent():
    off = training_offsets((2, 2), (8, 4))
    assert len(off) == 21 * 13 - 5 * 5
    white = np.zeros(64)
    white[0] = 1.0
    assert effective_training_cells(off, white, white) == pytest.approx(len(off))
    assert effective_training_cells_os(off, white, white, 0.75) == pytest.approx(len(off))
    # a Hann-windowed range axis correlates neighbours: fewer independent cells
    w2 = np.hanning(66)[1:-1] ** 2
    hann = np.abs(np.fft.fft(w2, 64) / w2.sum()) ** 2
    assert effective_training_cells(off, hann, white) < 0.8 * len(off)


@pytest.mark.parametrize("kind", ["ca", "os"])
def test_cfar_detect_false_alarms_on_white_exponential_cells(kind):
    """Independent exponential cells (square-law noise): the measured false-alarm rate is the
    design value within 15 % (Poisson spread ~5 % at 2600 expected alarms)."""
    pfa = 1e-2
    rng = np.random.default_rng(1)
    power = rng.exponential(size=(2, 384, 384))
    guard, train = (1, 1), (4, 3)
    n = len(training_offsets(guard, train))
    alpha = cfar_threshold_factor(kind, n, pfa, rank=0.75)
    mask = cfar_detect(power, kind=kind, guard=guard, train=train, alpha=alpha, rank=0.75)
    assert mask.mean() == pytest.approx(pfa, rel=0.15)


@pytest.mark.parametrize("kind", ["ca", "os"])
def test_chain_false_alarm_rate_on_noise_is_the_design_value(reference, kind):
    """Noise only through the whole chain (Hann range window, 3x zero-padded azimuth FFT,
    correlated cells): CFAR false alarms per range-azimuth cell within a factor of 2 of the
    design P_fa (here 1e-3; ~57 expected per frame, 4 frames). TX->RX leakage (a signal at
    ~0 m) is off; the board's impairments and the 12-bit ADC stay on."""
    radar = reference.with_updates(signal={"cfar_kind": kind, "cfar_pfa": 1e-3,
                                           "peak_grouping": False, "tx_rx_leakage_db": None,
                                           "min_range_m": 0.0})
    alarms = cells = 0
    for seed in range(4):
        frame = simulate_signal_frame(EMPTY, radar, seed=seed)
        alarms += frame.n_points
        cells += frame.range_azimuth_db.size
    rate = alarms / cells
    assert 0.5 * 1e-3 < rate < 2.0 * 1e-3, rate
    # a Poisson test against the *uncorrected* design (N instead of N_eff) would be further off
    assert frame.stats["cfar_n_eff"] < frame.stats["cfar_n_train"]


def test_range_doppler_cfar_false_alarm_rate(reference):
    """Full chirp cube, CA-CFAR on the range-Doppler detection matrix (192 non-coherent
    looks): false alarms per cell within a factor of 2 of the design P_fa."""
    radar = reference.with_updates(
        adc_samples=128, n_chirps=32, hardware={"if_highpass_hz": None},
        signal={"doppler": "full", "cfar_domain": "range-doppler", "cfar_pfa": 1e-2,
                "cfar_training_cells": (8, 6), "peak_grouping": False, "adc_bits": None,
                "tx_rx_leakage_db": None, "angle_sidelobe_db": 0.01})
    alarms = cells = 0
    for seed in range(3):
        frame = simulate_signal_frame(EMPTY, radar, seed=seed)
        alarms += frame.n_points        # one point per detection (strongest azimuth only)
        cells += radar.adc_samples * radar.n_chirps
    rate = alarms / cells
    assert 0.5e-2 < rate < 2.0e-2, rate
    assert frame.stats["cfar_looks"] == 192


def test_azimuth_row_is_the_86_element_cascade_row(reference):
    row = azimuth_row(reference)
    assert row.n_positions == 86 and len(row.n_dup) == 86      # filled lambda/2 row
    assert len(row.channels) == 9 * 16                          # TX4..TX12 x all RX
    assert row.n_dup.sum() == 144 and row.n_dup.max() > 1       # duplicates averaged
    assert np.allclose(row.averaging.sum(axis=0), 1.0)


def test_noise_floor_reported_matches_the_map(reference):
    """The reported noise floor (intensity scale) is the mean noise power of the range-azimuth
    map (exponential cells: the mean of 10^(dB/10) over the map)."""
    frame = simulate_signal_frame(EMPTY, reference.with_updates(
        hardware={"if_highpass_hz": None}, signal={"tx_rx_leakage_db": None}), seed=0)
    mean_db = 10 * np.log10(np.mean(10 ** (frame.range_azimuth_db.astype(np.float64) / 10)))
    # 12-bit ADC adds LSB^2/12 per rail (+0.09 dB at 60 dB full scale)
    assert mean_db == pytest.approx(frame.stats["noise_floor_db"], abs=0.15)
    # the per-cell values are exponential: a KS test does not reject at 1 %
    p = 10 ** (frame.range_azimuth_db[::7, ::5].astype(np.float64).ravel() / 10)
    assert stats.kstest(p / p.mean(), "expon").pvalue > 0.01
