"""IF synthesis of a TDM-MIMO FMCW radar from propagation paths (the reference radar's front end).

Every path of a :class:`~sim2radar.radar.paths.PathSet` becomes, for every TX/RX pair and
every chirp, one complex tone of the dechirped (IF) signal; the sum over paths, plus the
radar's own impairments, leakage and thermal noise, is what the ADCs of the cascade would
record. :mod:`sim2radar.radar.processing` then runs the device's chain on it.

Signal model
------------
Mixing the transmitted chirp with its echo delayed by ``tau`` gives, at time ``t'`` after the
first ADC sample of the chirp (TX x conj(RX) mixing; TI SWRA553 "Introduction to mmWave
sensing: FMCW radars", IF-signal section: ``f_IF = S tau``, ``phi_0 = 2 pi f_0 tau = 4 pi d /
lambda``)::

    x(t') = A exp(j 2 pi [f_s tau + S tau t' - S tau^2 / 2])                           (1)

with ``f_s`` = ``start_frequency_hz`` (the frequency at the first ADC sample: the sampled band
is ``[f_s, f_s + B]``, matching :attr:`RadarConfig.center_frequency_hz`), ``S`` the slope
[Hz/s] and ``- S tau^2 / 2`` the residual video phase (Carrara, Goodman & Majewski,
*Spotlight Synthetic Aperture Radar*, 1995, eq. (3.29) — negligible here but free). Each
TX/RX pair has its own delay (near field; :mod:`sim2radar.radar.paths`)::

    tau_{t,r}(T) = (|P_dep - tx_t| + inner + |P_arr - rx_r| + 2 rdot T) / c              (2)

``T`` being absolute time from the frame centre (the instant the PathSet describes) and
``rdot`` the path's ``range_rate_mps``. TDM-MIMO: in loop ``m`` the transmitters fire one
after the other in ``signal.tx_order``; TX ``t`` in slot ``s_t`` starts its first ADC sample
at (TI SWRA553, TDM-MIMO section; TIDEP-01012 §2.3 "chirp configuration")::

    T_{m,t} = (m N_tx + s_t) T_c + t_idle + t_adc - T_frame / 2,   T_c = chirp_period_s    (3)

``synthesis: time`` evaluates (1) with (2) at every sample (the reference; cost P x C x N
per chirp). ``synthesis: frequency`` makes each path one tone per chirp: with ``tau = tau_0 +
tau' t'`` (``tau' = 2 rdot / c``), (1) is linear in ``t'`` but for ``S tau' t'^2``, replaced by
its least-squares line ``S tau' (T t' - T^2/6)`` over the sampling window ``T`` (error
``<= S tau' T^2 / 6`` cycles: 1e-4 at 1 m/s for the cascade chirp). The tone's frequency is
``S tau_0 + tau' (f_s + S T)`` [Hz] (the IF frequency at mid-chirp: range-Doppler coupling)
and its phase at ``t' = 0`` follows from (1); the tones are spread onto a 2x oversampled frequency
grid with the "exponential of semicircle" kernel and inverse-FFT'd (a type-1 non-uniform FFT:
Barnett, Magland & af Klinteberg, SIAM J. Sci. Comput. 41(5), C479-C504, 2019; kernel width
``w = ceil(log10(1/eps)) + 1`` and ``beta = 2.30 w`` for oversampling 2, as in their FINUFFT).
The error is ~1e-6 of the per-sample signal, i.e. far below the thermal noise of any echo
whose per-sample SNR is below ~100 dB. Both give IF samples, so noise, ADC and processing are
the same code for both.

``synthesis: narrowband`` (the reference radar's default) makes the full chirp cube at the
cost of about one integrated frame. It keeps every channel's exact (near-field) phase but
shares one tone per path across the channels of a *sub-array* (:data:`NARROWBAND_SUBARRAYS`
runs of virtual azimuth positions): with ``tau_c = tau_s + delta_c`` about the sub-array's mean
delay ``tau_s``, (1) is ``x_c(t') = A e^{j 2 pi [f_s tau_s + S tau_s t' - S tau_s^2/2]} e^{j 2
pi delta_c (f_s + S (t' - tau_s))}`` and the second factor is taken at mid-window (``t' =
T/2``): exact at the window centre, it drops the range walk *within* a sub-array (``S
delta_c``: up to 3.4 range bins across the whole 86-element aperture at 60 deg, <= 0.5 bin
within one of 8 sub-arrays; the per-channel energy stays within 0.05 dB of ``time``,
tested). Per path and chirp ``m`` of TX ``t`` the slow-time factor is ``e^{j 2 pi f_D
T_{m,t}}`` with the Doppler ``f_D`` at mid-window; paths are grouped by ``f_D`` rounded to
1/:data:`DOPPLER_SUBBINS` of a Doppler bin (a tone at most 1/8 bin off, no leakage), each
group's fast-time tones gridded as in ``frequency`` (one sparse-times-dense product per
sub-array) and inverse-FFT'd to the group's fast-time samples ``y_g`` (one transform per group
and channel, where the chirps would need one per chirp), and the chirps formed by one matrix
product per channel over the groups, ``x[m] = sum_g e^{j 2 pi f_g T_{m,t}} y_g``. Left
out: the range migration over the frame (``2 rdot T / c``: <= 1.2 range bins at 1.5 m/s
radial over the 39 ms frame, <= 0.5 dB at the peak).

``doppler: integrated`` (static scenes) never forms the chirps: it returns directly the
Doppler-windowed sum over chirps ``sum_m w_m x_m`` (the zero-Doppler bin of the Doppler FFT),
each path weighted by ``sum_m w_m exp(j 2 pi f_c 2 rdot T_{m,t} / c)`` (``sum w`` when static)
and the thermal noise with variance ``sigma^2 sum_m w_m^2`` (independent chirps). Range
migration over the frame is ignored there; ``doppler: full`` synthesises every chirp with (2).

Amplitudes
----------
``|x|^2`` is power [W]: a path of tracer amplitude ``a`` (|a|^2 = sigma / (4 pi r^4),
:mod:`sim2radar.radar.returns`) has ``A = a sqrt(K_echo g_tx(dep) g_rx(arr)) H_IF(f_b)`` with
``K_echo`` = :func:`~sim2radar.radar.link_budget.echo_power_scale_w` (radar equation),
``g`` the one-way element power patterns (:func:`~sim2radar.radar.link_budget.
element_power_pattern`) at the departure / arrival direction seen from the array's phase
centre, and ``H_IF`` the IF filter (:func:`sim2radar.radar.receiver.if_filter_response`): a
first-order high-pass at ``if_highpass_hz`` and the anti-alias filter's pass band up to
``if_bandwidth_fraction * f_adc`` with the roll-off ``if_rolloff_db`` beyond (a return past the
unambiguous range aliases).
The ``1/r`` difference between elements (< 5 % at 2 m for the 0.17 m array) is neglected; the
phase difference is not.

Impairments (fixed per board, ``impairment_seed``): per-TX and per-RX complex gain errors
(each drawn with std/sqrt(2), so a virtual channel's error has the configured std), mutual
coupling between elements lambda/2 apart (a banded coupling matrix on the TX and on the RX
side: Friedlander & Weiss, IEEE TAP 39(3), 273-284, 1991, eq. (3)), TX->RX leakage (a tone at
the elements' separation ``|tx_t - rx_r|``, power ``tx_rx_leakage_db`` re the transmit power),
thermal noise ``k T F f_adc`` per complex sample (:func:`~sim2radar.radar.link_budget.
noise_power_w`) and an ``adc_bits`` mid-rise quantiser whose full scale sits
``adc_full_scale_db`` above the noise rms per rail (in ``integrated`` mode quantisation is the
additive uniform noise ``LSB^2 / 12`` per rail it becomes when the input spans many LSBs:
Widrow & Kollar, *Quantization Noise*, 2008, ch. 4).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
import warnings
from typing import Any

import numpy as np
import scipy.signal

from sim2radar.constants import SPEED_OF_LIGHT_M_S
from sim2radar.radar import link_budget
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.paths import PathSet
from sim2radar.radar.receiver import if_filter_response

__all__ = [
    "NUFFT_OVERSAMPLING",
    "NUFFT_WIDTH",
    "ChannelImpairments",
    "IFCube",
    "channel_impairments",
    "element_positions_m",
    "if_filter_response",
    "slot_times_s",
    "synthesize_if",
    "tx_slots",
    "window_weights",
]

log = logging.getLogger(__name__)

#: Oversampling of the NUFFT's frequency grid (Barnett et al. 2019: sigma = 2).
NUFFT_OVERSAMPLING = 2
#: Exponential-of-semicircle kernel width [grid points]; error ~10^-(w-1) (Barnett et al.).
NUFFT_WIDTH = 7
#: Kernel shape parameter per unit width for oversampling 2 (Barnett et al.: beta = 2.30 w).
NUFFT_BETA_PER_WIDTH = 2.30
#: (path, TX/RX pair) combinations synthesised per chunk: bounds the working memory (~100
#: bytes of float64/complex temporaries each, ~100 MB at this size).
CHUNK_PATH_CHANNELS = 1 << 20
#: Doppler groups per Doppler bin of the narrowband synthesis: a path's Doppler is rounded to
#: the nearest 1/4 bin (<= 1/8 bin = 0.006 m/s off, <= 0.22 dB weaker at the bin centre; a
#: tone at a slightly other frequency, no leakage — a slow-time NUFFT with 4 taps leaked
#: Doppler sidelobes 95 dB down, which TI's CFAR detects beside a metal plate).
DOPPLER_SUBBINS = 4
#: Sub-arrays of the narrowband synthesis: runs of virtual azimuth positions that share one
#: tone per path (the range walk across a sub-array is dropped; module doc).
NARROWBAND_SUBARRAYS = 8


# -- geometry and timing ------------------------------------------------------------------
def element_positions_m(radar: RadarConfig) -> tuple[np.ndarray, np.ndarray]:
    """TX and RX element positions in the radar frame [m].

    The preset's ``[azimuth, elevation]`` indices (units of lambda/2, ``lambda`` =
    :attr:`RadarConfig.wavelength_m`) map to ``y`` (left) and ``z`` (up); all elements lie in
    the plane ``x = 0``. The origin is the virtual array's phase centre: TX and RX positions
    are each shifted by half the mean virtual position, so the virtual positions ``tx_t +
    rx_r`` have zero mean.

    Sign convention: a target at azimuth ``+theta`` (left, ``y > 0``) is nearer to elements of
    larger ``y``; with the IF phase ``+2 pi f tau`` (module doc, eq. (1)) its virtual-channel
    phases fall as ``-k (tx + rx) . u``, and :mod:`sim2radar.radar.processing` beamforms with
    the matched ``exp(+j k (tx + rx) . u)``, so ``+theta`` is estimated at ``+theta``.

    Returns
    -------
    tx : (N_tx, 3) float64 [m]
    rx : (N_rx, 3) float64 [m]
    """
    half_wl_m = 0.5 * radar.wavelength_m
    tx = np.asarray(radar.tx_antennas_half_wl, dtype=np.float64).reshape(-1, 2)
    rx = np.asarray(radar.rx_antennas_half_wl, dtype=np.float64).reshape(-1, 2)
    centre = tx.mean(axis=0) + rx.mean(axis=0)  # mean virtual position [lambda/2]

    def to_m(idx: np.ndarray) -> np.ndarray:
        yz = (idx - 0.5 * centre) * half_wl_m
        return np.column_stack([np.zeros(len(idx)), yz[:, 0], yz[:, 1]])

    return to_m(tx), to_m(rx)


def tx_slots(radar: RadarConfig) -> np.ndarray:
    """(N_tx,) int — TDM slot of each transmitter within a loop (``signal.tx_order``)."""
    order = radar.signal.tx_order
    if order is None:
        return np.arange(radar.n_tx)
    if len(order) != radar.n_tx:
        raise ValueError(f"signal.tx_order has {len(order)} entries, the radar has "
                         f"{radar.n_tx} transmitters")
    slots = np.empty(radar.n_tx, dtype=np.int64)
    slots[np.asarray(order)] = np.arange(radar.n_tx)
    return slots


def slot_times_s(radar: RadarConfig) -> np.ndarray:
    """(n_chirps, N_tx) float64 — time of each chirp's first ADC sample from the frame centre
    [s] (module doc, eq. (3))."""
    t_c = radar.chirp_period_s
    slots = tx_slots(radar)
    m = np.arange(radar.n_chirps)[:, None]
    frame_s = radar.n_chirps * radar.n_tx * t_c
    return ((m * radar.n_tx + slots[None, :]) * t_c + radar.chirp_idle_time_s
            + radar.adc_start_time_s - 0.5 * frame_s)


def window_weights(name: str, n: int) -> np.ndarray:
    """(n,) float64 — a DFT-even (periodic) window (Harris, Proc. IEEE 66(1), 1978);
    ``"none"`` is rectangular; ``"hanning"`` is MATLAB's symmetric ``hanning(n)``,
    ``0.5 - 0.5 cos(2 pi k / (n + 1))`` for ``k = 1..n`` (no zero end points; the range window
    of TI's cascade chain, ``module_param.m``)."""
    if name == "none":
        return np.ones(n)
    if name == "hanning":
        return 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(1, n + 1) / (n + 1))
    return scipy.signal.get_window(name, n, fftbins=True).astype(np.float64)


# -- impairments --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class ChannelImpairments:
    """The board's fixed errors (drawn once from ``signal.impairment_seed``).

    Attributes
    ----------
    gain : (N_tx, N_rx) complex128 — complex gain error of each virtual channel [-].
    tx_coupling : (N_tx, N_tx) complex128 — TX mutual-coupling matrix [-] (identity: none).
    rx_coupling : (N_rx, N_rx) complex128 — RX mutual-coupling matrix [-].
    """

    gain: np.ndarray
    tx_coupling: np.ndarray
    rx_coupling: np.ndarray

    @property
    def is_identity(self) -> bool:
        return bool(np.all(self.gain == 1.0)
                    and np.array_equal(self.tx_coupling, np.eye(len(self.tx_coupling)))
                    and np.array_equal(self.rx_coupling, np.eye(len(self.rx_coupling))))


def _coupling_matrix(idx_half_wl: np.ndarray, coupling: float, rng: np.random.Generator
                     ) -> np.ndarray:
    """``I + c exp(j psi_ij)`` for element pairs exactly lambda/2 apart (banded, symmetric;
    Friedlander & Weiss 1991); ``psi`` uniform, fixed per board."""
    n = len(idx_half_wl)
    mat = np.eye(n, dtype=np.complex128)
    d = np.linalg.norm(idx_half_wl[:, None, :] - idx_half_wl[None, :, :], axis=2)
    i, j = np.nonzero(np.triu(np.isclose(d, 1.0), k=1))
    phase = rng.uniform(-math.pi, math.pi, len(i))
    mat[i, j] = coupling * np.exp(1j * phase)
    mat[j, i] = mat[i, j]
    return mat


def channel_impairments(radar: RadarConfig) -> ChannelImpairments:
    """The fixed per-board errors of :class:`ChannelImpairments` (deterministic)."""
    sig = radar.signal
    rng = np.random.default_rng(sig.impairment_seed)
    nt, nr = radar.n_tx, radar.n_rx
    s_db = sig.channel_gain_error_db / math.sqrt(2.0)
    s_rad = math.radians(sig.channel_phase_error_deg) / math.sqrt(2.0)
    g_db = rng.normal(0.0, 1.0, nt)[:, None] * s_db + rng.normal(0.0, 1.0, nr)[None, :] * s_db
    g_ph = rng.normal(0.0, 1.0, nt)[:, None] * s_rad + rng.normal(0.0, 1.0, nr)[None, :] * s_rad
    gain = 10.0 ** (g_db / 20.0) * np.exp(1j * g_ph)
    if sig.mutual_coupling_db is None:
        ctx, crx = np.eye(nt, dtype=np.complex128), np.eye(nr, dtype=np.complex128)
    else:
        c = 10.0 ** (sig.mutual_coupling_db / 20.0)
        ctx = _coupling_matrix(np.asarray(radar.tx_antennas_half_wl, float), c, rng)
        crx = _coupling_matrix(np.asarray(radar.rx_antennas_half_wl, float), c, rng)
    if sig.channel_gain_error_db == 0.0 and sig.channel_phase_error_deg == 0.0:
        gain = np.ones((nt, nr), dtype=np.complex128)
    return ChannelImpairments(gain=gain, tx_coupling=ctx, rx_coupling=crx)


# -- the result ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class IFCube:
    """Synthesised IF samples of one frame.

    Attributes
    ----------
    samples : (n_slow, N_tx, N_rx, N_adc) complex64 torch tensor [sqrt(W)] — ``n_slow`` =
        ``n_chirps`` (``doppler: full``) or 1 (``integrated``: the Doppler-windowed chirp sum).
    doppler_integrated : bool
    doppler_gain : float — coherent gain already applied along slow time [-]: ``sum_m w_m``
        when integrated, 1 otherwise.
    noise_power_w : float — thermal (+ quantisation) noise per complex sample of ``samples``
        [W].
    stats : dict — counts and seconds.
    """

    samples: Any
    doppler_integrated: bool
    doppler_gain: float
    noise_power_w: float
    stats: dict[str, Any]


# -- NUFFT helpers ------------------------------------------------------------------------
def _es_kernel(x: np.ndarray, width: int) -> np.ndarray:
    """Exponential-of-semicircle kernel ``exp(beta (sqrt(1 - (2x/w)^2) - 1))`` on ``|x| <= w/2``
    (x in grid units; Barnett et al. 2019), zero outside."""
    beta = NUFFT_BETA_PER_WIDTH * width
    z = 2.0 * x / width
    return np.exp(beta * (np.sqrt(np.clip(1.0 - z * z, 0.0, None)) - 1.0)) * (np.abs(z) <= 1)


def _es_kernel_inplace(torch, x, width: int):
    """:func:`_es_kernel` for ``|x| <= w/2`` (no support mask), overwriting ``x``."""
    beta = NUFFT_BETA_PER_WIDTH * width
    x.mul_(x).mul_(-4.0 / width**2).add_(1.0).clamp_(min=0.0).sqrt_()
    return x.sub_(1.0).mul_(beta).exp_()


def _kernel_ft(xi: np.ndarray, width: int) -> np.ndarray:
    """The kernel's Fourier transform ``Phi(xi) = int phi(x) cos(2 pi x xi) dx`` [grid units]
    at ``xi`` [cycles per grid unit], by 64-node Gauss-Legendre quadrature."""
    nodes, weights = np.polynomial.legendre.leggauss(64)
    x = 0.5 * width * nodes
    phi = _es_kernel(x, width) * 0.5 * width * weights
    xi = np.asarray(xi, dtype=np.float64)
    return (phi * np.cos(2.0 * np.pi * xi[..., None] * x)).sum(axis=-1)


@functools.lru_cache(maxsize=16)
def _deapodisation(n_samples: int, width: int, oversampling: int) -> np.ndarray:
    """(n_samples,) float64 — ``1 / Phi((n - N/2) / M)`` (:func:`_kernel_ft`)."""
    m = oversampling * n_samples
    return 1.0 / _kernel_ft((np.arange(n_samples) - n_samples // 2) / m, width)


def _torch():
    import torch

    return torch


# -- synthesis ----------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _PathTerms:
    """Per-path quantities shared by both synthesis modes (numpy, float64/complex128)."""

    amp: np.ndarray       # (P,) complex — A before per-channel and slow-time factors [sqrt(W)]
    d_tx: np.ndarray      # (P, N_tx) |P_dep - tx_t| [m]
    d_rx: np.ndarray      # (P, N_rx) |P_arr - rx_r| [m]
    inner: np.ndarray     # (P,) inner length [m]
    rate: np.ndarray      # (P,) range rate [m/s]


def _distances_m(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """(P, E) float64 ``|points_p - elements_e|`` [m], the squares summed coordinate by
    coordinate: the same values as ``np.linalg.norm(points[:, None] - elements, axis=2)`` (the
    same additions in the same order) at several times its speed (no (P, E, 3) temporaries, no
    reduction over an axis of 3, and a coordinate all elements share, such as the array
    plane's x = 0, is squared once per point)."""
    acc = None
    for k in range(3):
        e_k = elements[:, k]
        if np.all(e_k == e_k[0]):
            d = (points[:, k] - e_k[0])[:, None]                               # (P, 1)
        else:
            d = points[:, k, None] - e_k[None, :]                              # (P, E)
        d *= d
        if acc is None:
            acc = d
        elif acc.shape == np.broadcast_shapes(acc.shape, d.shape):
            acc += d
        else:
            acc = acc + d
    return np.sqrt(np.broadcast_to(acc, (len(points), len(elements))))


def _path_terms(paths: PathSet, radar: RadarConfig) -> tuple[_PathTerms, dict[str, int]]:
    tx_m, rx_m = element_positions_m(radar)
    dep = np.asarray(paths.departure_point_m, np.float64)
    arr = np.asarray(paths.arrival_point_m, np.float64)

    g = link_budget.two_way_pattern_gain(radar, dep, arr)
    rate = np.asarray(paths.range_rate_mps, np.float64)
    beat_hz = (radar.slope_hz_per_s * paths.path_length_m / SPEED_OF_LIGHT_M_S
               + 2.0 * rate * radar.start_frequency_hz / SPEED_OF_LIGHT_M_S)
    h = if_filter_response(radar, beat_hz)
    amp = (np.asarray(paths.amplitude, np.complex128)
           * np.sqrt(link_budget.echo_power_scale_w(radar) * g) * h)
    keep = amp != 0
    beyond = np.abs(beat_hz) > radar.hardware.if_bandwidth_fraction * radar.adc_sample_rate_hz
    counts = {"n_paths": len(paths), "n_paths_beyond_if_band": int(np.count_nonzero(beyond)),
              "n_paths_behind_elements": int(np.count_nonzero(g == 0))}
    dep, arr = dep[keep], arr[keep]
    terms = _PathTerms(
        amp=amp[keep],
        d_tx=_distances_m(dep, tx_m),
        d_rx=_distances_m(arr, rx_m),
        inner=np.asarray(paths.inner_length_m, np.float64)[keep],
        rate=rate[keep],
    )
    counts["n_paths_synthesised"] = int(keep.sum())
    return terms, counts


def _doppler_dc_gain(radar: RadarConfig, rate: np.ndarray, w_d: np.ndarray) -> np.ndarray:
    """(P, N_tx) complex128 — ``sum_m w_m exp(j 2 pi f_c 2 rdot T_{m,t} / c)`` (module doc)."""
    t = slot_times_s(radar)  # (M, T)
    out = np.empty((len(rate), radar.n_tx), dtype=np.complex128)
    k = 2.0 * np.pi * radar.center_frequency_hz * 2.0 / SPEED_OF_LIGHT_M_S
    step = max(1, (1 << 20) // max(1, t.size))
    for s in range(0, len(rate), step):
        ph = k * rate[s:s + step, None, None] * t[None, :, :]
        out[s:s + step] = np.einsum("m,pmt->pt", w_d, np.exp(1j * ph))
    return out


def _channel_delays(torch, terms: _PathTerms, sl: slice, device, t_shift_s=None):
    """(p, T, R) float64 round-trip delay [s] (eq. (2)); ``t_shift_s`` (T,) adds ``2 rdot T``."""
    c = SPEED_OF_LIGHT_M_S
    d_tx = torch.as_tensor(terms.d_tx[sl], device=device)
    d_rx = torch.as_tensor(terms.d_rx[sl], device=device)
    inner = torch.as_tensor(terms.inner[sl], device=device)
    length = d_tx[:, :, None] + inner[:, None, None] + d_rx[:, None, :]
    if t_shift_s is not None:
        rate = torch.as_tensor(terms.rate[sl], device=device)
        ts = torch.as_tensor(t_shift_s, device=device, dtype=torch.float64)
        length = length + (2.0 * rate[:, None] * ts[None, :])[:, :, None]
    return length / c


def _synth_frequency(torch, radar: RadarConfig, terms: _PathTerms, slow_gain: np.ndarray | None,
                     t_shift_s: np.ndarray | None, device):
    """IF samples (T, R, N) of one chirp (or the integrated sum) by gridding (module doc)."""
    n = radar.adc_samples
    m = NUFFT_OVERSAMPLING * n
    w = NUFFT_WIDTH
    nt, nr = radar.n_tx, radar.n_rx
    c = SPEED_OF_LIGHT_M_S
    f_s, slope, f_adc = radar.start_frequency_hz, radar.slope_hz_per_s, radar.adc_sample_rate_hz
    t_chirp = radar.sampling_time_s
    grid = torch.zeros(nt * nr * (m + w), dtype=torch.complex64, device=device)
    chan_base = (torch.arange(nt * nr, device=device) * (m + w)).reshape(1, nt, nr)
    n_paths = len(terms.amp)
    step = max(1, CHUNK_PATH_CHANNELS // (nt * nr))
    for s in range(0, n_paths, step):
        sl = slice(s, min(n_paths, s + step))
        tau = _channel_delays(torch, terms, sl, device, t_shift_s)          # (p, T, R) [s]
        rate = torch.as_tensor(terms.rate[sl], device=device)[:, None, None]
        dtau = 2.0 * rate / c                                               # d tau / dt [-]
        # eq. (1) with tau = tau0 + dtau t': the t'^2 term S dtau t'^2 replaced by its
        # least-squares line over the chirp, S dtau (T t' - T^2 / 6) (T = N / f_adc)
        beat_bins = (slope * tau + dtau * (f_s + slope * (t_chirp - tau))) * (n / f_adc)
        # phase at the first sample, plus exp(j pi beta) to centre the samples on n - N/2
        cycles = (f_s * tau - 0.5 * slope * tau * tau - slope * dtau * t_chirp**2 / 6.0
                  + 0.5 * beat_bins)
        ph = ((2.0 * math.pi) * torch.remainder(cycles, 1.0)).to(torch.float32)
        amp = torch.as_tensor(terms.amp[sl], device=device)[:, None, None]
        if slow_gain is not None:
            amp = amp * torch.as_tensor(slow_gain[sl], device=device)[:, :, None]
        val = (amp.to(torch.complex64) * torch.polar(torch.ones_like(ph), ph)).reshape(-1)
        u = beat_bins * NUFFT_OVERSAMPLING                                  # grid units
        l0 = torch.ceil(u - 0.5 * w)                                        # first grid point
        first = (l0 - u).to(torch.float32)                                  # in [-w/2, -w/2+1)
        base = (torch.remainder(l0.to(torch.int64), m) + chan_base).reshape(-1)
        for j in range(w):  # grid point l0 + j: shift the destination, not the index
            x = first + float(j)                                            # in [-w/2, w/2)
            kern = _es_kernel_inplace(torch, x, w).reshape(-1)
            grid[j:].index_add_(0, base, val * kern)
    grid = grid.reshape(nt, nr, m + w)
    folded = grid[..., :m].clone()
    folded[..., :w] += grid[..., m:]
    g = torch.fft.ifft(folded, dim=-1) * m
    idx = torch.remainder(torch.arange(n, device=device) - n // 2, m)
    deapod = torch.as_tensor(_deapodisation(n, w, NUFFT_OVERSAMPLING), device=device,
                             dtype=torch.float32)
    return g[..., idx] * deapod


def _synth_time(torch, radar: RadarConfig, terms: _PathTerms, slow_gain: np.ndarray | None,
                t_shift_s: np.ndarray | None, device):
    """IF samples (T, R, N) of one chirp by evaluating eq. (1)-(2) at every sample."""
    n = radar.adc_samples
    nt, nr = radar.n_tx, radar.n_rx
    c = SPEED_OF_LIGHT_M_S
    f_s, slope, f_adc = radar.start_frequency_hz, radar.slope_hz_per_s, radar.adc_sample_rate_hz
    t_n = torch.arange(n, device=device, dtype=torch.float64) / f_adc       # [s]
    out = torch.zeros(nt, nr, n, dtype=torch.complex128, device=device)
    n_paths = len(terms.amp)
    step = max(1, (1 << 21) // (nt * nr * n))
    for s in range(0, n_paths, step):
        sl = slice(s, min(n_paths, s + step))
        tau0 = _channel_delays(torch, terms, sl, device, t_shift_s)
        rate = torch.as_tensor(terms.rate[sl], device=device)[:, None, None, None]
        tau = tau0[..., None] + 2.0 * rate * t_n / c                       # (p, T, R, N)
        cycles = f_s * tau + slope * tau * t_n - 0.5 * slope * tau * tau
        ph = (2.0 * math.pi) * torch.remainder(cycles, 1.0)
        amp = torch.as_tensor(terms.amp[sl], device=device)[:, None, None]
        if slow_gain is not None:
            amp = amp * torch.as_tensor(slow_gain[sl], device=device)[:, :, None]
        out += (amp[..., None] * torch.polar(torch.ones_like(ph), ph)).sum(dim=0)
    return out.to(torch.complex64)


def _grid_rows(v, key, taps, n_rows: int):
    """``Y[key_p + j] += taps[p, j] v[p]`` for every path ``p`` and kernel tap ``j``: one sparse
    (CSR) x dense product, built on ``v``'s device. The paths are put in ``key`` order (a stable
    sort, so a row sums its paths in that order); the sparse matrix is built by counting and
    reads ``v``'s rows through its column indices, so ``v`` stays in path order.

    v : (P, C2) float32; key : (P,) int64 with ``key + w - 1 < n_rows``; taps : (P, w) float32;
    all torch on one device. Returns (n_rows, C2) float32.
    """
    import torch

    dev = v.device
    n_paths, w = taps.shape
    order = torch.sort(key, stable=True).indices
    key = key[order]
    # entry (p, j) lands in row key_p + j; within a row the entries are the paths of the keys
    # row - j for j = 0..w-1 (taps in order), each key's paths in sorted order: count them
    cnt = torch.bincount(key, minlength=n_rows)                               # paths per key
    first = torch.cumsum(cnt, 0) - cnt                                        # first sorted index
    rank = torch.arange(n_paths, device=dev) - first[key]                     # rank within key
    # before[j, r]: entries of row r from taps < j, i.e. sum_{i<j} cnt[r - i]
    before = torch.zeros((w, n_rows), dtype=torch.int64, device=dev)
    for j in range(1, w):
        before[j] = before[j - 1]
        before[j, j - 1:] += cnt[:n_rows - j + 1]
    per_row = before[w - 1].clone()
    per_row[w - 1:] += cnt[:n_rows - w + 1]                                   # all w taps
    crow = torch.zeros(n_rows + 1, dtype=torch.int64, device=dev)
    torch.cumsum(per_row, 0, out=crow[1:])
    rows = key[None, :] + torch.arange(w, device=dev)[:, None]                # (w, P)
    pos = (crow[rows] + before.gather(1, rows) + rank[None, :]).ravel()
    nnz = int(crow[-1])
    col = torch.empty(nnz, dtype=torch.int64, device=dev)
    val = torch.empty(nnz, dtype=torch.float32, device=dev)
    col[pos] = order.expand(w, n_paths).ravel()
    val[pos] = taps[order].T.ravel()
    with warnings.catch_warnings():  # "CSR support is in beta": the product is what we use
        warnings.simplefilter("ignore", UserWarning)
        sp = torch.sparse_csr_tensor(crow, col, val, (n_rows, n_paths), check_invariants=False)
    return sp @ v


def _subarrays(radar: RadarConfig, n_groups: int) -> list[np.ndarray]:
    """Virtual channels (flat ``t * N_rx + r``) in ``n_groups`` contiguous runs of virtual
    azimuth position (the delay differences within one run stay small)."""
    v = np.asarray(radar.virtual_array_half_wl)
    order = np.lexsort((v[:, 1], v[:, 0]))
    return [g for g in np.array_split(order, min(n_groups, len(order))) if len(g)]


def _synth_narrowband(torch, radar: RadarConfig, terms: _PathTerms, w_d: np.ndarray,
                      integrated: bool, device):
    """IF samples (n_slow, T, R, N) by the sub-array separable synthesis (module doc). The
    per-path work (delays, tones, kernel taps, the sparse grid) runs in torch float64 on
    ``device``: on a GPU nothing per path goes back to the host."""
    c = SPEED_OF_LIGHT_M_S
    n = radar.adc_samples
    m_grid = NUFFT_OVERSAMPLING * n
    w = NUFFT_WIDTH
    nt, nr = radar.n_tx, radar.n_rx
    f_s, slope, f_adc = radar.start_frequency_hz, radar.slope_hz_per_s, radar.adc_sample_rate_hz
    t_win = radar.sampling_time_s
    n_loops = radar.n_chirps
    t_loop = nt * radar.chirp_period_s
    two_pi = 2.0 * math.pi

    def dev64(a: np.ndarray):
        return torch.as_tensor(a, dtype=torch.float64, device=device)

    d_tx, d_rx = dev64(terms.d_tx), dev64(terms.d_rx)
    inner, rate = dev64(terms.inner), dev64(terms.rate)
    amp = torch.as_tensor(terms.amp, dtype=torch.complex128, device=device)
    dtau = 2.0 * rate / c                                                   # (P,) [-]
    # Doppler groups: each path's slow-time frequency (the Doppler at mid-window, the same for
    # every channel) rounded to 1 / DOPPLER_SUBBINS of a Doppler bin, not periodic
    mu = dtau * (f_s + 0.5 * slope * t_win) * t_loop                        # [cycles / loop]
    scale = DOPPLER_SUBBINS * n_loops
    g0 = torch.round(mu * scale).to(torch.int64)                            # half to even
    g_lo, g_hi = (int(g) for g in torch.aminmax(g0))
    n_groups = g_hi - g_lo + 1
    row_len = m_grid + w
    # exact per-channel delays (eq. (2) at the frame centre) about the path's mean delay: the
    # TX and RX parts [s], each small (array size / c), float64 before the subtraction
    subs = _subarrays(radar, NARROWBAND_SUBARRAYS)
    dt_mean, dr_mean = d_tx.mean(dim=1), d_rx.mean(dim=1)
    tau0 = (dt_mean + inner + dr_mean) / c                                  # (P,) [s]
    del_t = (d_tx - dt_mean[:, None]) / c                                   # (P, T) [s]
    del_r = (d_rx - dr_mean[:, None]) / c                                   # (P, R) [s]
    # each channel's phase at mid-window about the path's mean delay, e^{j 2 pi f_eff (delta_t
    # + delta_r)} = a TX factor times an RX factor (f_eff of the path's mean delay for every
    # sub-array: the difference is < 1e-4 cycle)
    f_eff0 = f_s + slope * (0.5 * t_win - tau0)                             # (P,) [Hz]

    def cis(cycles, magnitude=None):
        """e^{j 2 pi cycles} (times ``magnitude``), complex64; the phase wrapped in float64."""
        phase = (two_pi * torch.remainder(cycles, 1.0)).to(torch.float32)
        mag = torch.ones_like(phase) if magnitude is None else magnitude.to(torch.float32)
        return torch.polar(mag, phase)

    a_t = cis(f_eff0[:, None] * del_t)                                      # (P, T)
    b_r = cis(f_eff0[:, None] * del_r)                                      # (P, R)
    amp_abs = amp.abs()
    amp_arg = torch.angle(amp) / two_pi                                     # [cycles]
    # slow time: each group's tone e^{j 2 pi mu_g s} at every chirp's start s = T / T_loop
    # [loops from the frame centre], per TX slot (the TDM offsets)
    s_mt = slot_times_s(radar) / t_loop                                     # (M, T)
    g_abs = np.arange(g_lo, g_lo + n_groups)
    e = np.exp(2j * np.pi * np.remainder(s_mt[:, :, None] * g_abs[None, None, :] / scale,
                                         1.0))                              # (M, T, G)
    if integrated:
        e = np.einsum("m,mtg->tg", w_d, e)[:, None, :]                      # (T, 1, G)
    else:
        e = np.transpose(e, (1, 0, 2))                                      # (T, M, G)
    e_t = torch.as_tensor(e.astype(np.complex64), device=device)           # (T, S, G)
    taps_at = torch.arange(w, dtype=torch.float64, device=device)
    group_row = (g0 - g_lo) * row_len
    # per sub-array: its fast-time grid (wrapped by the kernel width), each Doppler group's
    # grid inverse-FFT'd to its fast-time samples (G transforms per channel where the chirps
    # would need S, and only the N samples kept), then one product per channel over the
    # groups, x[m] = sum_g e^{j 2 pi f_g T_m} y_g, into the sub-array's rows of `chirps`
    # (the channels in sub-array order, `perm`; put back in order at the end)
    perm = np.concatenate(subs)
    n_slow = e.shape[1]
    # the inverse FFT's scale M (a power of two: exact) folded into the deapodisation
    deapod = torch.as_tensor(m_grid * _deapodisation(n, w, NUFFT_OVERSAMPLING), device=device,
                             dtype=torch.float32)
    h = n // 2
    chirps = torch.empty((nt * nr, n_slow, n), dtype=torch.complex64, device=device)
    start = 0
    for chans in subs:
        # one tone per path and sub-array at the sub-array's mean delay (eq. (1); frequency and
        # phase as in _synth_frequency), each channel's phase exact at mid-window
        rel_mean = (del_t @ dev64(np.bincount(chans // nr, minlength=nt))
                    + del_r @ dev64(np.bincount(chans % nr, minlength=nr))) / len(chans)  # [s]
        tau = tau0 + rel_mean
        beat_bins = (slope * tau + dtau * (f_s + slope * (t_win - tau))) * (n / f_adc)
        cycles = (f_s * tau - 0.5 * slope * tau * tau - slope * dtau * t_win**2 / 6.0
                  + 0.5 * beat_bins + amp_arg - f_eff0 * rel_mean)
        u = beat_bins * NUFFT_OVERSAMPLING
        l0 = torch.ceil(u - 0.5 * w)
        taps = _es_kernel_inplace(torch, (l0 - u)[:, None] + taps_at, w).to(torch.float32)
        key = group_row + torch.remainder(l0.to(torch.int64), m_grid)
        chans_t = torch.as_tensor(chans, device=device)
        # (advanced indexing gathers these columns ~3x faster than index_select on a CPU; the
        # products in place: no new (P, c) arrays)
        wts = a_t[:, chans_t // nr]
        wts.mul_(b_r[:, chans_t % nr]).mul_(cis(cycles, amp_abs)[:, None])
        v = torch.view_as_real(wts).reshape(len(amp), -1)
        part = torch.view_as_complex(_grid_rows(v, key, taps, n_groups * row_len).reshape(
            -1, len(chans), 2)).reshape(n_groups, row_len, len(chans)).permute(2, 0, 1)
        folded = part[..., :m_grid].contiguous()                            # (c, G, M)
        folded[..., :w] += part[..., m_grid:]
        spec = torch.fft.ifft(folded, dim=-1)
        del folded
        # fast-time sample k is grid bin k - n//2 (mod M): the grid's last n//2 bins, then its
        # first n - n//2
        y = torch.empty((len(chans), n_groups, n), dtype=torch.complex64, device=device)
        torch.mul(spec[..., m_grid - h:], deapod[:h], out=y[..., :h])
        torch.mul(spec[..., :n - h], deapod[h:], out=y[..., h:])
        del spec
        torch.bmm(e_t[chans_t // nr], y, out=chirps[start:start + len(chans)])  # (c, S, N)
        start += len(chans)
    out = torch.empty((n_slow, nt * nr, n), dtype=torch.complex64, device=device)
    out.transpose(0, 1).index_copy_(0, torch.as_tensor(perm, device=device), chirps)
    return out.reshape(n_slow, nt, nr, n)                                   # (S, T, R, N)


def _leakage(radar: RadarConfig) -> np.ndarray:
    """(T, R, N) complex128 — TX->RX leakage tones [sqrt(W)] (one chirp)."""
    tx_m, rx_m = element_positions_m(radar)
    p_t_w = link_budget.transmit_power_w(radar)
    a = math.sqrt(p_t_w * 10.0 ** (radar.signal.tx_rx_leakage_db / 10.0))
    tau = np.linalg.norm(tx_m[:, None, :] - rx_m[None, :, :], axis=2) / SPEED_OF_LIGHT_M_S
    t_n = np.arange(radar.adc_samples) / radar.adc_sample_rate_hz
    f_s, slope = radar.start_frequency_hz, radar.slope_hz_per_s
    cycles = f_s * tau[..., None] + slope * tau[..., None] * t_n - 0.5 * slope * tau[..., None] ** 2
    h = if_filter_response(radar, slope * tau)[..., None]
    return a * h * np.exp(2j * np.pi * np.remainder(cycles, 1.0))


def _couple(torch, ctx, crx, x):
    """``y[s, a, c, n] = sum_(b, d) ctx[a, b] crx[c, d] x[s, b, d, n]``: the TX and RX coupling
    matrices applied one after the other (two small matrix products, 7x fewer operations than
    the 192 x 192 Kronecker product; float32 rounding differs from it by ~5e-7 of the peak)."""
    s, nt, nr, n = x.shape
    y = torch.matmul(crx, x)                                               # (S, T, R, N)
    return torch.matmul(ctx, y.reshape(s, nt, nr * n)).reshape(s, nt, nr, n)


def _add_thermal_noise(torch, x, seed: int, power_w: float, on_device: bool | None = None):
    """Add circular complex Gaussian noise of ``power_w`` [W] per sample to ``x`` (complex64,
    in place).

    On the CPU from NumPy's ``default_rng(seed)`` (real parts, then imaginary parts, each scaled
    in float32); on any other torch device (or with ``on_device``) drawn there, from a
    ``torch.Generator`` seeded with ``seed`` (no host draw and no 25 MB copy per frame; a
    different stream of the same distribution).
    """
    scale = math.sqrt(0.5 * power_w)
    if on_device is None:
        on_device = x.device.type != "cpu"
    rails = torch.view_as_real(x)                                          # (..., 2) float32
    if not on_device:
        rng = np.random.default_rng(seed)
        part = np.empty(x.shape, np.float32)  # one rail at a time, drawn in place
        for k in range(2):
            rng.standard_normal(dtype=np.float32, out=part)
            part *= np.float32(scale)
            rails[..., k].add_(torch.from_numpy(part))
        return x
    gen = torch.Generator(device=x.device).manual_seed(int(seed))
    re = torch.randn(x.shape, generator=gen, device=x.device, dtype=torch.float32)
    im = torch.randn(x.shape, generator=gen, device=x.device, dtype=torch.float32)
    return x.add_(torch.complex(re, im).mul_(scale))


def _adc_lsb(radar: RadarConfig) -> float:
    """ADC step [sqrt(W)] per rail: full scale ``adc_full_scale_db`` above the per-rail noise
    rms ``sqrt(k T F f_adc / 2)``, over ``2^bits`` levels spanning +-full scale."""
    rail_rms = math.sqrt(0.5 * link_budget.noise_power_w(radar))
    full_scale = rail_rms * 10.0 ** (radar.signal.adc_full_scale_db / 20.0)
    return 2.0 * full_scale / 2 ** radar.signal.adc_bits


def _quantise_(torch, x, lsb: float, bits: int):
    """Mid-rise quantiser with clipping, applied to I and Q of ``x`` (complex64) in place."""
    top = 2 ** (bits - 1)
    rails = torch.view_as_real(x)
    rails.div_(lsb).floor_().clamp_(-top, top - 1).add_(0.5).mul_(lsb)
    return x


def synthesize_if(paths: PathSet, radar: RadarConfig, *, seed: int | None = None,
                  device=None) -> IFCube:
    """IF samples of every TX/RX pair (and chirp) for ``paths`` at ``radar``.

    Parameters
    ----------
    paths : PathSet — radar frame; amplitudes in the tracer's normalisation.
    radar : RadarConfig — chirp, array, ``hardware`` (link budget, IF filter) and ``signal``
        (``synthesis``, ``doppler``, impairments, ADC).
    seed : int or None — thermal-noise seed; None: no noise (deterministic).
    device : torch device or None — None picks :func:`sim2radar.hardware.torch_device`.

    Returns
    -------
    IFCube — ``samples`` (n_slow, N_tx, N_rx, N_adc) complex64 [sqrt(W)].
    """
    torch = _torch()
    if device is None:
        from sim2radar.hardware import torch_device

        device = torch_device()
    sig = radar.signal
    t0 = time.perf_counter()
    terms, stats = _path_terms(paths, radar)
    w_d = window_weights(sig.doppler_window, radar.n_chirps)
    synth = _synth_time if sig.synthesis == "time" else _synth_frequency
    nt, nr, n = radar.n_tx, radar.n_rx, radar.adc_samples
    imp = channel_impairments(radar)
    leak = _leakage(radar) if sig.tx_rx_leakage_db is not None else None
    moving = bool(np.any(terms.rate != 0.0))
    stats.update(moving_paths=int(np.count_nonzero(terms.rate)), synthesis=sig.synthesis,
                 doppler=sig.doppler, device=str(device))

    integrated = sig.doppler == "integrated"
    if integrated and moving:
        log.warning("doppler: integrated keeps only the zero-Doppler bin; %d moving paths "
                    "are attenuated as they would be there (use doppler: full for a moving "
                    "rig)", stats["moving_paths"])
    if sig.synthesis == "narrowband":
        x = (_synth_narrowband(torch, radar, terms, w_d, integrated, device) if len(terms.amp)
             else torch.zeros((1 if integrated else radar.n_chirps, nt, nr, n),
                              dtype=torch.complex64, device=device))
        doppler_gain = float(w_d.sum()) if integrated else 1.0
        noise_scale = float(np.sum(w_d**2)) if integrated else 1.0
    elif integrated:
        dc = _doppler_dc_gain(radar, terms.rate, w_d) if moving else None
        x = synth(torch, radar, terms, dc, None, device)
        if dc is None:
            x = x * float(w_d.sum())
        x = x[None]
        doppler_gain = float(w_d.sum())
        noise_scale = float(np.sum(w_d**2))
    else:
        times = slot_times_s(radar)
        if moving:
            x = torch.stack([synth(torch, radar, terms, None, times[k], device)
                             for k in range(radar.n_chirps)])
        else:  # static: every chirp is the same
            x = synth(torch, radar, terms, None, None, device)[None].expand(
                radar.n_chirps, nt, nr, n).clone()
        doppler_gain, noise_scale = 1.0, 1.0
    t_synth = time.perf_counter() - t0

    # board impairments: coupling (antenna level) then channel gain errors (electronics)
    if not imp.is_identity:
        ctx = torch.as_tensor(imp.tx_coupling, device=device, dtype=torch.complex64)
        crx = torch.as_tensor(imp.rx_coupling, device=device, dtype=torch.complex64)
        gain = torch.as_tensor(imp.gain, device=device, dtype=torch.complex64)
        x = _couple(torch, ctx, crx, x).mul_(gain[None, :, :, None])
    if leak is not None:  # (x is this function's own array from here on: changed in place)
        x.add_(torch.as_tensor(leak * (doppler_gain if sig.doppler == "integrated" else 1.0),
                               device=device, dtype=torch.complex64)[None])

    # thermal noise added here; quantisation noise (Widrow & Kollar: LSB^2/12 per rail) is
    # drawn with it when integrated, produced by the quantiser itself when full
    added_w = link_budget.noise_power_w(radar) * noise_scale
    noise_out_w = added_w
    if sig.adc_bits is not None:
        lsb = _adc_lsb(radar)
        noise_out_w += 2.0 * lsb**2 / 12.0 * noise_scale
        if sig.doppler == "integrated":
            added_w = noise_out_w
            top = 2 ** (sig.adc_bits - 1) * lsb
            per_chirp = x / doppler_gain
            stats["adc_clipped_fraction"] = float(
                ((per_chirp.real.abs() > top) | (per_chirp.imag.abs() > top)).float().mean())
    if seed is not None:
        _add_thermal_noise(torch, x, seed, added_w)
    if sig.adc_bits is not None and sig.doppler == "full":
        lsb = _adc_lsb(radar)
        top = 2 ** (sig.adc_bits - 1) * lsb
        stats["adc_clipped_fraction"] = float(
            ((x.real.abs() > top) | (x.imag.abs() > top)).float().mean())
        _quantise_(torch, x, lsb, sig.adc_bits)
    stats.update(seconds_synthesis=t_synth, seconds_if_total=time.perf_counter() - t0,
                 noise_power_w=noise_out_w,
                 echo_power_scale_w=link_budget.echo_power_scale_w(radar))
    return IFCube(samples=x, doppler_integrated=sig.doppler == "integrated",
                  doppler_gain=doppler_gain, noise_power_w=noise_out_w, stats=stats)
