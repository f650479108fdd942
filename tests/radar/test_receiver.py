"""The receiver's IF chain in the binning ray tracer (sim2radar/radar/receiver.py).

Physical expectations: a return in the first nine tenths of the range axis passes the IF
chain untouched; one in the last tenth is attenuated by the anti-alias roll-off (-20 dB at
0.95 R_max, -40 dB at R_max); a return beyond R_max is not lost but aliases to ``r - R_max``
at the stop-band attenuation, in the NumPy twin (binning.deposit) and in the Dr.Jit tracer
alike.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.radar import RadarScene, array_geometry, deposit
from sim2radar.radar.receiver import ALIAS_INTERVALS, if_filter_response, range_bin_gain
from tests.radar.conftest import facing_plate


def test_range_bin_gain_is_the_if_response_at_each_bins_beat_frequency(mmwcas):
    gain = range_bin_gain(mmwcas)
    n = mmwcas.n_range_bins
    assert gain.shape == (ALIAS_INTERVALS * n,)
    bins = np.array([0, n // 2, int(0.9 * n), int(0.95 * n), n, int(1.05 * n), int(1.5 * n)])
    f = bins * mmwcas.adc_sample_rate_hz / n
    np.testing.assert_allclose(gain[bins], if_filter_response(mmwcas, f))
    db = 20 * np.log10(np.abs(gain[bins]))
    assert db[:3] == pytest.approx([0.0, 0.0, 0.0], abs=1e-9)       # pass band to 0.9 f_adc
    assert db[3] == pytest.approx(-20.0, abs=0.5)                    # 0.95 R_max
    assert db[4] == pytest.approx(-40.0)                             # R_max
    # linear in dB between (f_adc, -40 dB) and (1.1 f_adc, -60 dB), then flat
    assert db[5] == pytest.approx(-40.0 - 200.0 * (bins[5] / n - 1.0)) and db[6] == pytest.approx(-60.0)


def test_deposit_attenuates_near_r_max_and_aliases_beyond(mmwcas):
    geom = array_geometry(mmwcas)
    r_max, dr = mmwcas.max_range_m, mmwcas.range_resolution_m
    a = np.array([1e-3 + 0j])

    def bin_power(r_m: float) -> tuple[int, float]:
        acc = deposit(np.array([r_m]), np.zeros(1), np.zeros(1), a, mmwcas)
        p = (np.abs(acc.aperture(geom)) ** 2).sum(axis=(1, 2))
        return int(np.argmax(p)), float(p.max())

    i_ref, p_ref = bin_power(0.5 * r_max)
    i_far, p_far = bin_power(0.95 * r_max)
    assert i_far == round(0.95 * r_max / dr) and i_ref == round(0.5 * r_max / dr)
    assert 10 * math.log10(p_far / p_ref) == pytest.approx(-20.0, abs=0.5)
    i_alias, p_alias = bin_power(r_max + 1.0)
    true_bin = round((r_max + 1.0) / dr)
    assert i_alias == true_bin - mmwcas.n_range_bins             # seen at r - R_max
    want = 20 * math.log10(abs(range_bin_gain(mmwcas)[true_bin]))
    assert 10 * math.log10(p_alias / p_ref) == pytest.approx(want, abs=1e-6)
    assert -60.0 <= want <= -50.0


def test_tracer_shows_a_plate_beyond_r_max_aliased_and_attenuated(mmwcas):
    """A metal plate 0.8 m beyond R_max: the Dr.Jit tracer puts its return in bin ``i - N``
    at the roll-off's attenuation of its true bin (compared with the same scene traced with a
    flat IF response, which places it in the same aliased bin)."""
    radar = mmwcas.with_updates(azimuth_fov_deg=20.0, elevation_fov_deg=20.0,
                                ray_spacing_deg=0.25, max_bounces=1)
    flat = radar.with_updates(hardware={"if_bandwidth_fraction": 1.0,
                                        "if_rolloff_db": [[1.5, 0.0]]})
    r_true = radar.max_range_m + 0.8
    scene = RadarScene([facing_plate(r_true, size=1.0, material="metal")])
    geom = array_geometry(radar)

    def profile(cfg) -> np.ndarray:
        acc = scene.trace(cfg).accumulator
        return (np.abs(acc.aperture(geom).astype(np.complex128)) ** 2).sum(axis=(1, 2))

    p, p_flat = profile(radar), profile(flat)
    true_bin = round(r_true / radar.range_resolution_m)
    alias_bin = true_bin - radar.n_range_bins
    assert abs(int(np.argmax(p)) - alias_bin) <= 1 and abs(int(np.argmax(p_flat)) - alias_bin) <= 1
    window = slice(alias_bin - 2, alias_bin + 3)
    drop_db = 10 * math.log10(p[window].sum() / p_flat[window].sum())
    want = 20 * math.log10(abs(range_bin_gain(radar)[true_bin]))
    assert drop_db == pytest.approx(want, abs=0.5)
    assert want < -50.0
