"""The receiver's IF chain, shared by both radars: what the IF filters do to a return of a
given beat frequency, and hence of a given range.

An FMCW return of round-trip length ``L`` [m] beats at ``f_b = S L / c`` [Hz] (``S`` the chirp
slope; plus ``2 rdot f_c / c`` on a moving rig). Before the ADC the AWR2243's IF chain passes it
through (TI SWRS223, "Receiver" section):

* a first-order high-pass (HPF1, ``hardware.if_highpass_hz``; 175 kHz is the lowest corner,
  -3 dB at 0.27 m for the cascade's chirp): ``H_hp = j f/f_c / (1 + j f/f_c)``;
* the anti-alias / decimation filter of complex-1x sampling: flat up to
  ``if_bandwidth_fraction * f_adc`` (0.9: TI's "IF bandwidth ... 90 % of the sampling rate"),
  then the stop-band roll-off ``if_rolloff_db`` (an assumption: TI publishes no stop-band figure;
  -40 dB at ``f_adc``, -60 dB from 1.1 ``f_adc``).

Complex sampling at ``f_adc`` maps beat frequencies ``[0, f_adc)`` onto range bins
``[0, R_max)``; a return beyond ``R_max`` keeps its beat frequency, which the sampling aliases
by ``f_adc`` onto ``r - R_max`` -- at the roll-off's attenuation. So a receiver does **not**
show returns from the last tenth of its range axis at full strength, and does not drop longer
paths: it folds them back, weakened.

* :func:`if_filter_response` — the complex response at a beat frequency (the signal-level
  synthesis, :mod:`sim2radar.radar.fmcw`, multiplies every path by it);
* :func:`range_bin_gain` — the same response at the centre beat frequency of each *true* range
  bin, over several unambiguous intervals: the binning ray tracer
  (:meth:`sim2radar.radar.RadarScene.trace`) multiplies each return by the gain of its true bin
  and deposits it in that bin modulo the number of range bins (the aliasing).
"""

from __future__ import annotations

import numpy as np

from sim2radar.radar.config import RadarConfig

__all__ = ["ALIAS_INTERVALS", "if_filter_response", "range_bin_gain"]

#: Unambiguous range intervals :func:`range_bin_gain` tabulates (a return beyond them takes the
#: last entry: the roll-off's floor).
ALIAS_INTERVALS = 2


def if_filter_response(radar: RadarConfig, beat_hz: np.ndarray) -> np.ndarray:
    """Complex IF-chain response at beat frequency ``beat_hz`` [Hz] [-].

    First-order high-pass ``H = j f/f_c / (1 + j f/f_c)`` at ``hardware.if_highpass_hz``
    (AWR2243 HPF1; TI SWRS223), times the anti-alias / decimation filter: 1 for ``|f| <=
    if_bandwidth_fraction * f_adc``, beyond that the gain of ``hardware.if_rolloff_db``
    (linear in dB between its points, the last value beyond them). Nothing is removed: a return
    beyond the unambiguous range keeps its beat frequency, which complex sampling aliases by
    ``f_adc``, at the filter's attenuation.
    """
    f = np.asarray(beat_hz, dtype=np.float64)
    hw = radar.hardware
    frac = np.abs(f) / radar.adc_sample_rate_hz
    xs = [hw.if_bandwidth_fraction] + [float(p[0]) for p in hw.if_rolloff_db]
    ys = [0.0] + [float(p[1]) for p in hw.if_rolloff_db]
    gain_db = np.interp(frac, xs, ys, left=0.0, right=ys[-1])
    h = (10.0 ** (gain_db / 20.0)).astype(np.complex128)
    if hw.if_highpass_hz is not None:
        jf = 1j * f / hw.if_highpass_hz
        h = h * jf / (1.0 + jf)
    return h


def range_bin_gain(radar: RadarConfig, intervals: int = ALIAS_INTERVALS) -> np.ndarray:
    """IF response at the centre beat frequency ``i f_adc / N`` of true range bin ``i``.

    Parameters
    ----------
    radar : RadarConfig — chirp (``N = adc_samples`` bins over ``[0, R_max)``) and hardware.
    intervals : int — unambiguous intervals tabulated (``intervals * N`` bins).

    Returns
    -------
    (intervals * N,) complex128 [-] — bin ``i`` of the table is seen in range bin ``i mod N``.
    """
    n = radar.n_range_bins
    beat_hz = np.arange(int(intervals) * n) * (radar.adc_sample_rate_hz / n)
    return if_filter_response(radar, beat_hz)
