"""The processing chain (sim2radar.radar.processing): the virtual grid, false-alarm rates of
the chain's CFAR designs on noise through the whole front end, the reported noise floor."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from sim2radar.radar import cfar, load_radar_config
from sim2radar.radar.paths import PathSet
from sim2radar.radar.processing import virtual_grid
from sim2radar.radar.signal import simulate_signal_frame

EMPTY = PathSet.point_targets(np.zeros((0, 3)))


@pytest.fixture(scope="module")
def reference():
    return load_radar_config("ti-mmwcas-reference")


def test_virtual_grid_is_the_86_by_7_cascade_grid(reference):
    """TI's DOA_beamformingFFT_2D.m grid: 86 azimuth x 7 elevation lambda/2 positions; the
    elevation-0 row holds 144 channels on 86 positions; 'first' keeps one channel per position
    (the earliest TX slot), 'average' averages them."""
    first = virtual_grid(reference)
    assert first.weights.shape == (192, 86, 7)
    assert first.row == 0 and first.n_row_positions == 86
    assert sorted(np.flatnonzero(first.filled.any(axis=0))) == [0, 1, 4, 6]
    assert np.allclose(first.weights.sum(axis=0)[first.filled], 1.0)
    assert (first.weights > 0).sum() == first.filled.sum()          # one channel per position
    assert np.allclose(first.noise_gain[first.filled], 1.0)
    avg = virtual_grid(reference.with_updates(signal={"virtual_duplicates": "average"}))
    assert (avg.weights[:, :, 0] > 0).sum() == 144
    assert avg.noise_gain[:, 0].min() < 1.0                          # duplicates averaged


@pytest.mark.parametrize("kind", ["ca", "os"])
def test_range_azimuth_chain_false_alarm_rate_on_noise_is_the_design_value(reference, kind):
    """Noise only through the whole chain in the range-azimuth domain (Hann range window, 3x
    zero-padded azimuth FFT, correlated cells): CFAR false alarms per range-azimuth cell within
    a factor of 2 of the design P_fa (1e-3; ~57 expected per frame, 4 frames). TX->RX leakage
    is off; the board's impairments and the 12-bit ADC stay on."""
    radar = reference.with_updates(signal={
        "doppler": "integrated", "cfar_domain": "range-azimuth", "cfar_kind": kind,
        "cfar_threshold": None, "cfar_pfa": 1e-3, "cfar_guard_cells": (2, 2),
        "cfar_training_cells": (8, 4), "peak_grouping": False, "tx_rx_leakage_db": None,
        "elevation_gate_deg": 90.0, "azimuth_gate_deg": 90.0, "min_range_m": 0.0})
    alarms = cells = 0
    for seed in range(4):
        frame = simulate_signal_frame(EMPTY, radar, seed=seed)
        alarms += frame.n_points
        cells += frame.range_azimuth_db.size
    rate = alarms / cells
    assert 0.5 * 1e-3 < rate < 2.0 * 1e-3, rate
    assert frame.stats["cfar_n_eff"] < frame.stats["cfar_n_train"]


@pytest.fixture(scope="module")
def noise_rd(reference):
    """Range-Doppler maps (linear power) of noise-only frames of the reference chain."""
    radar = reference.with_updates(hardware={"if_highpass_hz": None},
                                   signal={"tx_rx_leakage_db": None})
    maps, stats_ = [], None
    for seed in range(3):
        frame = simulate_signal_frame(EMPTY, radar, seed=seed)
        maps.append(10 ** (frame.range_doppler_db.astype(np.float64) / 10))
        stats_ = frame.stats
    return np.stack(maps), stats_


@pytest.mark.parametrize("pfa", [1e-2, 1e-3])
def test_range_doppler_cfar_false_alarm_rate_on_noise(noise_rd, pfa):
    """TI's two passes on the range-Doppler map of noise (192 non-coherently summed channels,
    Hann-correlated range bins, 12-bit ADC): at thresholds designed for P_fa, each pass's false
    alarms per cell are within a factor of 2 of the design value (~2,000-40,000 cells)."""
    maps, st = noise_rd
    assert st["cfar_looks"] == 192
    for axis, guard, train, n_eff, edges in ((1, 8, 8, st["cfar_n_eff_range"], "ti"),
                                             (2, 0, 4, st["cfar_n_eff_doppler"], "wrap")):
        alpha = cfar.cfar_threshold_factor("caso", n_eff, pfa, looks=192)
        det, _ = cfar.cfar_1d(maps, axis=axis, kind="caso", guard=guard, train=train,
                              alpha=alpha, edges=edges, discard=(10, 20))
        tested = maps[:, 10:-20, :] if axis == 1 else maps
        rate = det.sum() / tested.size
        assert 0.5 * pfa < rate < 2.0 * pfa, (axis, rate)


def test_ti_chain_reports_no_points_on_noise(noise_rd, reference):
    """With TI's K0 = 5 / 3 the design false-alarm rate is below 1e-50: a noise-only frame of
    the default chain has no point (leakage off)."""
    _, st = noise_rd
    assert st["cfar_design_pfa_range"] < 1e-14 and st["n_detections"] == 0


def test_noise_floor_reported_matches_the_map(reference):
    """The reported noise floor (intensity scale) is the mean noise power of the range-azimuth
    map (exponential cells: the mean of 10^(dB/10) over the map; integrated Doppler: one map)."""
    frame = simulate_signal_frame(EMPTY, reference.with_updates(
        hardware={"if_highpass_hz": None},
        signal={"tx_rx_leakage_db": None, "doppler": "integrated",
                "cfar_domain": "range-azimuth", "cfar_kind": "ca", "range_dc_removal": False}),
        seed=0)
    mean_db = 10 * np.log10(np.mean(10 ** (frame.range_azimuth_db.astype(np.float64) / 10)))
    # 12-bit ADC adds LSB^2/12 per rail (+0.09 dB at 60 dB full scale)
    assert mean_db == pytest.approx(frame.stats["noise_floor_db"], abs=0.15)
    # the per-cell values are exponential: a KS test does not reject at 1 %
    p = 10 ** (frame.range_azimuth_db[::7, ::5].astype(np.float64).ravel() / 10)
    assert stats.kstest(p / p.mean(), "expon").pvalue > 0.01
