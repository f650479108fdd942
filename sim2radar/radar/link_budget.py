"""Link budget: echo power, receiver noise and element patterns from the preset's hardware.

The tracer's field normalisation (:mod:`sim2radar.radar.returns`) gives ``|a|^2 = sigma /
(4 pi r^4)`` for a monostatic target of RCS ``sigma`` [m^2] at range ``r`` [m]. The radar
equation (Richards, *Fundamentals of Radar Signal Processing*, 2nd ed., eq. (2.17))::

    P_r = P_t G_t G_r lambda^2 sigma / ((4 pi)^3 r^4 L_sys)

so the received power per unit ``|a|^2`` is ``P_t G_t G_r lambda^2 / ((4 pi)^2 L_sys)`` [W]
(:func:`echo_power_scale_w`). Thermal noise of a complex-baseband receiver sampled at ``f_s``
(noise bandwidth ``f_s``): ``N = k T F f_s`` [W] per complex sample (Richards eq. (2.29) with
``B = f_s``; :func:`noise_power_w`).

After coherent processing over ``N_adc`` samples, ``N_chirps`` chirps and ``N_virtual``
channels (range FFT, Doppler FFT, beamforming), a point target's SNR grows by the processing
gain ``G_p = N_adc N_chirps N_virtual`` (rectangular windows; tapered windows lose their
coherent-gain ratio, applied by the signal-level chain itself). The ray tracer's coherent cube
is the result of that processing in ``|a|^2`` units, so its receiver noise per cell is
(:func:`noise_power_per_cell`)::

    N0 = k T F f_s / (echo_power_scale * G_p)        [sim. |a|^2 units]

Element patterns: one-way power patterns ``g(theta) = cos(theta)^q`` in each plane, ``q`` such
that ``g = 1/2`` at half the -3 dB beamwidth (a common fit to patch-antenna patterns, e.g.
Balanis, *Antenna Theory*, 4th ed., §6.10 cos^q element model); zero beyond 90 deg. The
signal-level simulator applies them per path: the TX pattern in the path's departure direction,
the RX pattern in its arrival direction (:func:`two_way_pattern_gain`), both seen from the
array's phase centre (the radar-frame origin).
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.constants import BOLTZMANN_J_K
from sim2radar.radar.config import RadarConfig

__all__ = [
    "direction_angles",
    "echo_power_scale_w",
    "transmit_power_w",
    "two_way_pattern_gain",
    "noise_power_w",
    "processing_gain",
    "noise_power_per_cell",
    "noise_floor_db",
    "pattern_exponent",
    "element_power_pattern",
]


def _db(x_db: float) -> float:
    return 10.0 ** (x_db / 10.0)


def transmit_power_w(radar: RadarConfig) -> float:
    """Output power of one transmitter ``P_t`` [W] (``hardware.tx_power_dbm``)."""
    return 1e-3 * _db(radar.hardware.tx_power_dbm)


def echo_power_scale_w(radar: RadarConfig) -> float:
    """Received power [W] per unit ``|a|^2`` at boresight: ``P_t G_t G_r lambda^2 / ((4 pi)^2
    L_sys)`` (radar equation, Richards eq. (2.17))."""
    hw = radar.hardware
    p_t = transmit_power_w(radar)
    return (p_t * _db(hw.tx_gain_dbi) * _db(hw.rx_gain_dbi) * radar.wavelength_m**2
            / ((4.0 * math.pi) ** 2 * _db(hw.system_loss_db)))


def noise_power_w(radar: RadarConfig) -> float:
    """Thermal noise per complex ADC sample ``k T F f_s`` [W] (Richards eq. (2.29))."""
    hw = radar.hardware
    return BOLTZMANN_J_K * hw.temperature_k * _db(hw.noise_figure_db) * radar.adc_sample_rate_hz


def processing_gain(radar: RadarConfig) -> float:
    """Coherent gain ``N_adc * N_chirps * N_virtual`` of range FFT, Doppler FFT and
    beamforming with rectangular windows [-]."""
    return float(radar.adc_samples * radar.n_chirps * radar.n_virtual)


def noise_power_per_cell(radar: RadarConfig) -> float:
    """Receiver noise per cell of the ray tracer's coherent cube [sim. ``|a|^2`` units]."""
    return noise_power_w(radar) / (echo_power_scale_w(radar) * processing_gain(radar))


def noise_floor_db(radar: RadarConfig) -> float:
    """:func:`noise_power_per_cell` in dB (what ``detection.noise_floor_db`` used to type in)."""
    return 10.0 * math.log10(noise_power_per_cell(radar))


def pattern_exponent(hpbw_deg: float) -> float:
    """``q`` of the ``cos^q`` power pattern whose -3 dB full width is ``hpbw_deg`` [deg]."""
    half = math.radians(0.5 * float(hpbw_deg))
    if not 0.0 < half < 0.5 * math.pi:
        raise ValueError(f"beamwidth must lie in (0, 180) deg, got {hpbw_deg}")
    return math.log(0.5) / math.log(math.cos(half))


def element_power_pattern(
    radar: RadarConfig, azimuth_rad: np.ndarray, elevation_rad: np.ndarray
) -> np.ndarray:
    """One-way element power gain relative to boresight, ``cos^qa(az) cos^qe(el)`` [-].

    Parameters
    ----------
    azimuth_rad, elevation_rad : arrays [rad] (broadcast), radar frame (+ = left / up).

    Returns
    -------
    array in [0, 1] — 0 beyond +-90 deg in either plane.
    """
    qa = pattern_exponent(radar.hardware.azimuth_hpbw_deg)
    qe = pattern_exponent(radar.hardware.elevation_hpbw_deg)
    ca = np.clip(np.cos(np.asarray(azimuth_rad, dtype=np.float64)), 0.0, 1.0)
    ce = np.clip(np.cos(np.asarray(elevation_rad, dtype=np.float64)), 0.0, 1.0)
    return ca**qa * ce**qe


def direction_angles(vectors: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation [rad] of radar-frame vectors (x forward, y left, z up).

    Parameters
    ----------
    vectors : (N, 3) [m]

    Returns
    -------
    azimuth_rad : (N,) — ``atan2(y, x)`` (+ = left).
    elevation_rad : (N,) — ``atan2(z, hypot(x, y))`` (+ = up).
    """
    v = np.asarray(vectors, dtype=np.float64).reshape(-1, 3)
    return np.arctan2(v[:, 1], v[:, 0]), np.arctan2(v[:, 2], np.hypot(v[:, 0], v[:, 1]))


def two_way_pattern_gain(
    radar: RadarConfig, departure_m: np.ndarray, arrival_m: np.ndarray
) -> np.ndarray:
    """Two-way element power gain ``g_tx(departure) g_rx(arrival)`` relative to boresight [-].

    Parameters
    ----------
    departure_m, arrival_m : (N, 3) [m] — first / last interaction points of each path, radar
        frame (directions seen from the array's phase centre).

    Returns
    -------
    (N,) float64 in [0, 1].
    """
    return (element_power_pattern(radar, *direction_angles(departure_m))
            * element_power_pattern(radar, *direction_angles(arrival_m)))
