"""Link budget (sim2radar.radar.link_budget): radar equation, kTBF noise, element patterns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.constants import BOLTZMANN_J_K
from sim2radar.radar import link_budget, load_radar_config


@pytest.fixture(scope="module")
def radar():
    return load_radar_config("ti-mmwcas-reference")


def test_echo_scale_is_the_radar_equation(radar):
    """P_t G_t G_r lambda^2 / (4 pi)^2 with 12 dBm, 10 dBi, 10 dBi at 3.8 mm: 1.45e-7 W, so a
    1 m^2 target at 5 m (|a|^2 = 1 / (4 pi 5^4)) returns -77.4 dBm (Richards eq. (2.17))."""
    k = link_budget.echo_power_scale_w(radar)
    expected = 10 ** (12 / 10) * 1e-3 * 10 * 10 * radar.wavelength_m**2 / (4 * math.pi) ** 2
    assert k == pytest.approx(expected, rel=1e-12)
    p_r_dbm = 10 * math.log10(k / (4 * math.pi * 5.0**4) / 1e-3)
    assert p_r_dbm == pytest.approx(-77.4, abs=0.1)
    assert link_budget.transmit_power_w(radar) == pytest.approx(10 ** 1.2 * 1e-3)


def test_noise_is_ktfb_at_the_sampling_rate(radar):
    """k T F f_s: 290 K, 14 dB, 6.4 MHz -> -92.0 dBm per complex sample."""
    n = link_budget.noise_power_w(radar)
    assert n == pytest.approx(BOLTZMANN_J_K * 290 * 10**1.4 * 6.4e6)
    assert 10 * math.log10(n / 1e-3) == pytest.approx(-92.0, abs=0.1)


@pytest.mark.parametrize("hpbw", [30.0, 100.0, 140.0])
def test_pattern_is_half_power_at_half_beamwidth(radar, hpbw):
    r = radar.with_updates(hardware={"azimuth_hpbw_deg": hpbw, "elevation_hpbw_deg": hpbw})
    half = math.radians(hpbw / 2)
    assert link_budget.element_power_pattern(r, half, 0.0) == pytest.approx(0.5)
    assert link_budget.element_power_pattern(r, 0.0, -half) == pytest.approx(0.5)
    assert link_budget.element_power_pattern(r, 0.0, 0.0) == 1.0


def test_pattern_is_zero_behind_and_falls_monotonically(radar):
    az = np.radians(np.linspace(0, 180, 37))
    g = link_budget.element_power_pattern(radar, az, 0.0)
    assert np.all(np.diff(g) <= 0) and g[-1] == 0.0
    assert link_budget.element_power_pattern(radar, math.radians(95), 0.0) == 0.0


def test_two_way_gain_uses_departure_and_arrival_directions(radar):
    """A bistatic path leaving at 40 deg azimuth and arriving from 10 deg up: the product of
    the TX pattern at departure and the RX pattern at arrival."""
    dep = np.array([[3 * math.cos(math.radians(40)), 3 * math.sin(math.radians(40)), 0.0]])
    arr = np.array([[4 * math.cos(math.radians(10)), 0.0, 4 * math.sin(math.radians(10))]])
    g = link_budget.two_way_pattern_gain(radar, dep, arr)
    expected = (link_budget.element_power_pattern(radar, math.radians(40), 0.0)
                * link_budget.element_power_pattern(radar, 0.0, math.radians(10)))
    assert g[0] == pytest.approx(expected)
    az, el = link_budget.direction_angles(np.vstack([dep, arr]))
    assert np.degrees(az) == pytest.approx([40, 0], abs=1e-9)
    assert np.degrees(el) == pytest.approx([0, 10], abs=1e-9)
