"""The reference radar's processing chain: IF samples -> point cloud, as TI's 4-chip cascade
MIMO example processes a frame.

The anchor is TI's MATLAB example ``4chip_cascade_MIMO_example`` (mmWave Studio 3.0; public
copies e.g. GitHub ``Chngzz/radar-data-processing`` @990aad3): ``rangeProcCascade.m``,
``DopplerProcClutterRemove.m``, ``CFAR_CASO_Range.m``, ``CFAR_CASO_Doppler_overlap.m``,
``CFAR_CASO/datapath.m``, ``DOA_beamformingFFT_2D.m``, ``DOA_BF_PeakDet_loc.m`` with the
defaults of ``module_param.m`` (the preset ``ti-mmwcas-reference`` cites each value). Stages:

1. **Range FFT** per chirp and channel: the chirp's mean over its samples removed
   (``signal.range_dc_removal``; TI: always), ``signal.range_window`` (TI: MATLAB's symmetric
   ``hanning(N)``), FFT; bin ``k`` <-> beat frequency ``k f_adc / N``, range ``k c / (2 B)``
   (TI SWRA553, range-resolution section).
2. **Doppler FFT** across chirps with ``signal.doppler_window`` (TI: none) and, with
   ``signal.doppler_clutter_removal`` (TI: off), each range bin's mean over the chirps
   subtracted first; ``fftshift``:
   bin ``d`` <-> ``f_D = (d - D/2) / (N_chirps T_loop)``, radial velocity ``f_D lambda / 2``
   (positive = receding; ``T_loop = N_tx T_c``). ``doppler: integrated`` has one
   (zero-Doppler) bin.
3. **TDM phase compensation**: TX ``t`` fires in slot ``s_t``, so a target of Doppler ``f_D``
   adds ``2 pi f_D s_t T_c`` to its channels; each Doppler bin's channels are multiplied by
   ``exp(-j 2 pi f_D s_t T_c)`` = TI's ``exp(-j s_t 2 pi k / (N_tx D))`` with ``k = d - D/2``
   (``CFAR_CASO/datapath.m``, applied there to the detected cells only; Bechter, Roos &
   Waldschmidt, IEEE MWCL 27(11), 2017, eq. (4)).
4. **Detection** (``signal.cfar_domain``):

   * ``range-doppler`` (TI's point path): the non-coherently integrated map ``sum_v |X_v|^2``
     over all virtual channels; one CFAR pass along range on every Doppler column (TI:
     CASO, 8 reference + 8 guard cells per side, ``K0 = 5``, the first 10 and last 20 range
     bins never tested, the ends padded with copies of the tested stretch's own first / last
     cells), one along Doppler, circular, on the range hits (CASO, 4 reference, 0 guard,
     ``K0 = 3``); a cell is a detection when it passes both (:mod:`sim2radar.radar.cfar`). No
     peak grouping (``signal.peak_grouping`` adds 3x3 local maxima).
   * ``range-azimuth`` (TI's display heatmap, not its point path): a 2-D CA or OS CFAR on each
     Doppler bin's range-azimuth map (training rectangle minus guard rectangle, circular),
     optional 3x3(x3) local maxima, a point's Doppler bin within ``doppler_sidelobe_db`` of
     its range-azimuth cell's strongest.

   Thresholds are ``signal.cfar_threshold`` (linear, TI's ``K0``) or designed from
   ``signal.cfar_pfa`` with the looks and independent-cell counts of the map
   (:func:`sim2radar.radar.cfar.cfar_threshold_factor`); ``stats`` carries the design
   false-alarm rate of either.
5. **Angles** at each detection (``DOA_beamformingFFT_2D.m``): the virtual array as a grid of
   lambda/2 positions (86 in azimuth x 7 in elevation for the cascade), channels sharing a
   position reduced by ``signal.virtual_duplicates`` (TI: the first in firing order); an
   ``azimuth_fft_size`` FFT over the fullest row (TI: 256, no window), whose *magnitude*
   spectrum's peaks within ``angle_sidelobe_db`` of its strongest are points (TI's hysteresis
   search, :func:`sim2radar.radar.cfar.hysteresis_peaks`); per azimuth peak an
   ``elevation_fft_size`` FFT across the rows at that azimuth bin, its peaks within
   ``elevation_sidelobe_db`` (TI: 0 dB, the maximum). Azimuth bins are uniform in ``u =
   sin(az) cos(el)`` (``u_k = 2 (k - A/2) / A``), elevation bins in ``sin(el)``; the
   beamformer is matched to the IF phase convention of :mod:`sim2radar.radar.fmcw` (``Z(u) =
   sum_v x_v exp(+j pi v u)``, ``v`` in lambda/2 units): ``+u`` is left (``+y``), up (``+z``).
   Points beyond ``azimuth_gate_deg`` / ``elevation_gate_deg`` are dropped (TI: 80 / 20).
6. **Points** ``x y z intensity_db doppler_mps``: with ``signal.interpolate: false`` (TI) at
   bin positions — range = bin x ``c / 2B``, Doppler = (bin - D/2) x velocity bin, angles at
   their FFT bins; with ``true`` each refined by a parabola through the log powers of the peak
   and its two neighbours (:func:`sim2radar.radar.cfar.parabolic_peak`) and the range
   corrected for the range-Doppler coupling. ``y = r u``, ``z = r sin(el)``, ``x = sqrt(r^2 -
   y^2 - z^2)`` (TI's code multiplies ``y`` by ``cos(el)`` once more, which the direction
   cosine ``u`` already contains). Calibration: TI calibrates each TX/RX pair's phase and
   frequency from a corner-reflector capture (``calibrationCascade.m``); the synthesised board
   carries only the residue (``channel_gain_error_db``, ``channel_phase_error_deg``).

Intensity scale
---------------
A point's ``intensity_db = 10 log10(4 pi |a|^2)``, the ray tracer's scale
(:mod:`sim2radar.radar.returns`), with ``|a|^2 = P / (K_echo G^2)``: ``P`` the power of the
azimuth spectrum at the point [W per sample^2], ``K_echo`` =
:func:`~sim2radar.radar.link_budget.echo_power_scale_w` and ``G = (sum w_range) (sum
w_doppler) (sum w_azimuth over the row's positions)`` the coherent gain of the three FFTs. A
point target of RCS ``sigma`` at boresight thus reads ``sigma [dBsm] - 40 log10 r``; off
boresight the element patterns lower it. The thermal noise per range-Doppler-azimuth cell on
the same scale is ``stats["noise_floor_db"]``; ``intensity_db - noise_floor_db`` is the
point's SNR.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import Any

import numpy as np
from scipy import ndimage

from sim2radar.radar import cfar, link_budget
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.fmcw import IFCube, tx_slots, window_weights

__all__ = [
    "ProcessingResult",
    "VirtualGrid",
    "process_if",
    "virtual_grid",
]


# -- virtual array ------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class VirtualGrid:
    """The virtual array as a grid of lambda/2 positions, for FFT beamforming.

    Attributes
    ----------
    weights : (C, n_az, n_el) float64 — channel -> grid position (flat channel ``t * N_rx +
        r``): 1 for the channel kept at a position (``first``) or ``1 / n`` for each of ``n``
        averaged channels, 0 elsewhere [-].
    filled : (n_az, n_el) bool — positions with at least one channel.
    noise_gain : (n_az, n_el) float64 — ``sum`` of the squared weights at each position: the
        thermal-noise variance of a position relative to one channel's [-].
    row : int — the elevation row with the most azimuth positions (the azimuth FFT's row).
    """

    weights: np.ndarray
    filled: np.ndarray
    noise_gain: np.ndarray
    row: int

    @property
    def n_azimuth(self) -> int:
        return int(self.weights.shape[1])

    @property
    def n_elevation(self) -> int:
        return int(self.weights.shape[2])

    @property
    def n_row_positions(self) -> int:
        return int(np.count_nonzero(self.filled[:, self.row]))


def virtual_grid(radar: RadarConfig) -> VirtualGrid:
    """The virtual array's lambda/2 grid (``signal.virtual_duplicates`` resolves channels that
    share a position: ``first`` keeps the one whose TX fires first, as TI's
    ``DOA_beamformingFFT_2D.m`` does with MATLAB's ``unique``; ``average`` averages them).

    Raises
    ------
    ValueError — virtual positions off the lambda/2 grid, or more positions than the FFTs.
    """
    v = np.asarray(radar.virtual_array_half_wl, dtype=np.float64)
    if not np.allclose(v, np.round(v)):
        raise ValueError("FFT beamforming needs virtual positions on the lambda/2 grid")
    pos = (np.round(v) - np.round(v).min(axis=0)).astype(np.int64)
    n_az, n_el = int(pos[:, 0].max()) + 1, int(pos[:, 1].max()) + 1
    sig = radar.signal
    if n_az > sig.azimuth_fft_size or n_el > sig.elevation_fft_size:
        raise ValueError(f"the virtual array spans {n_az} x {n_el} positions; "
                         f"signal.azimuth_fft_size ({sig.azimuth_fft_size}) and "
                         f"elevation_fft_size ({sig.elevation_fft_size}) must be at least that")
    n_ch = len(pos)
    weights = np.zeros((n_ch, n_az, n_el))
    slot = np.repeat(tx_slots(radar), radar.n_rx)            # firing slot of each channel
    flat = pos[:, 0] * n_el + pos[:, 1]
    for cell in np.unique(flat):
        chans = np.flatnonzero(flat == cell)
        a, e = divmod(int(cell), n_el)
        if sig.virtual_duplicates == "first":
            weights[chans[np.argmin(slot[chans])], a, e] = 1.0
        else:
            weights[chans, a, e] = 1.0 / len(chans)
    filled = weights.sum(axis=0) > 0
    noise_gain = (weights**2).sum(axis=0)
    row = int(np.argmax(filled.sum(axis=0)))
    return VirtualGrid(weights=weights, filled=filled, noise_gain=noise_gain, row=row)


# -- result -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class ProcessingResult:
    """Output of :func:`process_if`.

    Attributes
    ----------
    points : (N, 5) float32 — x, y, z [m] (radar frame), intensity [dB] (module doc),
        radial velocity [m/s] (positive = receding); strongest first.
    range_m : (n_range,) float32 — range-bin centres [m].
    azimuth_sin : (n_az,) float32 — ``u = sin(az) cos(el)`` of the azimuth bins in the FOV [-].
    range_azimuth_db : (n_range, n_az) float32 or None — max over Doppler of the azimuth map
        of the virtual array's row, on the intensity scale [dB] (None: ``heatmap=False``).
    range_doppler_db : (n_range, n_doppler) float32 — the non-coherently integrated map ``sum_v
        |X_v|^2`` [dB re 1 W per sample^2] (what the range-doppler CFAR runs on).
    noise_floor_db : float — thermal noise per range-Doppler-azimuth cell, intensity scale [dB].
    stats : dict — seconds per stage, counts, CFAR design.
    range_doppler_cube : torch tensor or None — (n_doppler, N_tx, N_rx, n_range) complex64
        after range/Doppler FFT and TDM compensation (``keep_cube=True``).
    """

    points: np.ndarray
    range_m: np.ndarray
    azimuth_sin: np.ndarray
    range_azimuth_db: np.ndarray | None
    range_doppler_db: np.ndarray
    noise_floor_db: float
    stats: dict[str, Any]
    range_doppler_cube: Any = None


@dataclasses.dataclass(frozen=True)
class _Front:
    """Range/Doppler FFT output and its scales (module doc, stages 1-3)."""

    x: Any                     # (D, T, R, N) complex64 torch, TDM-compensated
    w_r: np.ndarray
    w_d: np.ndarray
    noise_sample_w: float      # noise per complex IF sample [W]
    doppler_noise: float       # sum of w_d^2 (1 when integrated)
    t_loop_s: float


def _front_end(cube: IFCube, radar: RadarConfig) -> _Front:
    import torch

    sig = radar.signal
    x = cube.samples
    device = x.device
    n = x.shape[-1]
    w_r = window_weights(sig.range_window, n)
    w_d = window_weights(sig.doppler_window, radar.n_chirps)
    w_r_t = torch.as_tensor(w_r, device=device, dtype=torch.float32)
    # one new array, then in place (the cube's samples are the caller's, left as they are)
    if sig.range_dc_removal:
        x = torch.sub(x, x.mean(dim=-1, keepdim=True)).mul_(w_r_t)
    else:
        x = x * w_r_t
    big = torch.fft.fft(x, dim=-1)
    del x
    t_loop = radar.n_tx * radar.chirp_period_s
    if cube.doppler_integrated:
        return _Front(big, w_r, w_d, cube.noise_power_w, 1.0, t_loop)
    n_dop = big.shape[0]
    if np.any(w_d != 1.0):  # (a rectangular window multiplies by exact ones)
        big.mul_(torch.as_tensor(w_d, device=device, dtype=torch.float32)[:, None, None, None])
    if sig.doppler_clutter_removal:
        big.sub_(big.mean(dim=0, keepdim=True))
    spec = torch.fft.fft(big, dim=0)
    f_d = (np.arange(n_dop) - n_dop // 2) / (n_dop * t_loop)              # [Hz]
    slot_s = tx_slots(radar) * radar.chirp_period_s                       # [s]
    comp = torch.as_tensor(np.exp(-2j * np.pi * f_d[:, None] * slot_s[None, :]), device=device,
                           dtype=torch.complex64)[:, :, None, None]      # (D, T, 1, 1)
    # fftshift along Doppler and the TDM compensation in one pass: bin k - D/2 is row k of the
    # shifted cube, FFT row (k - D/2) mod D
    h = n_dop - n_dop // 2                                                # rows before 0 Hz
    torch.mul(spec[h:], comp[:n_dop - h], out=big[:n_dop - h])
    torch.mul(spec[:h], comp[n_dop - h:], out=big[n_dop - h:])
    return _Front(big, w_r, w_d, cube.noise_power_w, float(np.sum(w_d**2)), t_loop)


def _gate(radar: RadarConfig) -> tuple[float, float]:
    """|sin| limits of the azimuth and elevation gates."""
    sig = radar.signal
    az = sig.azimuth_gate_deg if sig.azimuth_gate_deg is not None else 0.5 * radar.azimuth_fov_deg
    el = (sig.elevation_gate_deg if sig.elevation_gate_deg is not None
          else 0.5 * radar.elevation_fov_deg)
    return math.sin(math.radians(min(az, 90.0))), math.sin(math.radians(min(el, 90.0)))


def _threshold(kind: str, given: float | None, n_eff: float, looks: int, radar: RadarConfig
               ) -> tuple[float, float]:
    """(alpha, design false-alarm rate) of one CFAR pass."""
    sig = radar.signal
    if given is not None:
        alpha = float(given)
        if kind == "caso":
            return alpha, cfar.caso_false_alarm_rate(alpha, n_eff, looks)
        return alpha, float("nan")
    return cfar.cfar_threshold_factor(kind, n_eff, sig.cfar_pfa, looks=looks,
                                      rank=sig.cfar_os_rank), sig.cfar_pfa


def _spectrum_values(values, n_fft: int):
    """:func:`_spectrum_bins` before its fftshift (bin ``k`` at index ``(k + n/2) mod n``)."""
    import torch

    return torch.fft.ifft(values, n=n_fft, dim=-1) * n_fft


def _spectrum_bins(values, n_fft: int):
    """``Z(u_k) = sum_v x_v exp(+j pi v u_k)``, ``u_k = 2 (k - n/2) / n``, over the last axis
    (positions 0..V-1): an inverse FFT, fftshifted (module doc, stage 5)."""
    import torch

    return torch.fft.fftshift(_spectrum_values(values, n_fft), dim=-1)


def _row_signals(torch, xc, row_mat: np.ndarray):
    """``y[d, n, a] = sum_c xc[d, c, n] row_mat[c, a]``: the azimuth row's position signals
    from the channels (``xc`` (D, C, N) complex64, ``row_mat`` (C, A_pos) real weights).

    With at most one channel per position (``virtual_duplicates: first``, TI) it is a gather
    times the weight, the same values as the product (the other terms are exact zeros) at a
    hundredth of its cost; with averaged duplicates the product itself.
    """
    device = xc.device
    if np.all(np.count_nonzero(row_mat, axis=0) <= 1):
        chan = np.argmax(row_mat != 0, axis=0)                            # (A_pos,)
        weight = row_mat[chan, np.arange(row_mat.shape[1])]               # 0 where unfilled
        y = xc[:, torch.as_tensor(chan, device=device), :]                # (D, A_pos, N)
        y = y * torch.as_tensor(weight, device=device, dtype=torch.float32)[None, :, None]
        return y.transpose(1, 2)
    mat = torch.as_tensor(row_mat, device=device, dtype=torch.complex64)
    return torch.einsum("dcn,ca->dna", xc, mat)


def _azimuth_power(torch, xc, row_mat: np.ndarray, n_az: int):
    """(D, N, A) float32 — ``|Z|^2`` of the row's azimuth spectrum (:func:`_spectrum_bins`) at
    every cell of ``xc`` (D, C, N), fftshifted."""
    y_row = _row_signals(torch, xc, row_mat)                              # (D, N, A_pos)
    # |.|^2 before the fftshift (a permutation: the same values, half the bytes moved)
    return torch.fft.fftshift(_spectrum_values(y_row, n_az).abs().square(), dim=-1)


def process_if(cube: IFCube, radar: RadarConfig, *, noise_free: bool = False,
               keep_cube: bool = False, heatmap: bool = True) -> ProcessingResult:
    """Run the chain (module doc) on synthesised IF samples.

    Parameters
    ----------
    cube : IFCube — from :func:`sim2radar.radar.fmcw.synthesize_if`.
    radar : RadarConfig — the same config the cube was synthesised with.
    noise_free : bool — the cube has no noise: CFAR then runs on the *expected* power (the
        maps plus the known noise per cell), so detections are deterministic.
    keep_cube : bool — return the range-Doppler cube.
    heatmap : bool — also form the range-azimuth map of every (Doppler, range) cell
        (``range_azimuth_db``). The range-doppler CFAR does not need it: without it the
        azimuth spectra are taken only at the cells the points read (a frame's few hundred
        detections and their neighbours), the same values. The range-azimuth CFAR always
        forms it.
    """
    import torch

    sig = radar.signal
    timings: dict[str, float] = {}
    t = time.perf_counter()
    front = _front_end(cube, radar)
    X = front.x
    device = X.device
    n_dop, nt, nr, n = X.shape
    timings["seconds_range_doppler_fft"] = time.perf_counter() - t

    # virtual grid and scales
    grid = virtual_grid(radar)
    row_w = grid.weights[:, :, grid.row]                                  # (C, A)
    w_a = np.zeros(grid.n_azimuth)
    filled_row = grid.filled[:, grid.row]
    w_a[filled_row] = window_weights(sig.azimuth_window, grid.n_azimuth)[filled_row]
    k_echo = link_budget.echo_power_scale_w(radar)
    gain = front.w_r.sum() * front.w_d.sum() * w_a.sum()
    to_a2 = 1.0 / (k_echo * gain**2)
    cell_noise = front.noise_sample_w * np.sum(front.w_r**2) * front.doppler_noise
    noise_az = cell_noise * float(np.sum(w_a**2 * grid.noise_gain[:, grid.row]))
    noise_floor_db = 10.0 * math.log10(4.0 * math.pi * noise_az * to_a2)
    n_az = sig.azimuth_fft_size
    u = (np.arange(n_az) - n_az // 2) * 2.0 / n_az
    gate_az, gate_el = _gate(radar)
    fov = np.abs(u) <= math.sin(0.5 * radar.azimuth_fov_rad) + 1e-12

    # the range-azimuth map of the row (every cell; the heatmap and the range-azimuth CFAR)
    t = time.perf_counter()
    xc = X.reshape(n_dop, nt * nr, n)
    row_mat = row_w * w_a[None, :]
    power_t = ra = None
    if heatmap or sig.cfar_domain != "range-doppler":
        power_t = _azimuth_power(torch, xc, row_mat, n_az)                # (D, N, A)
        ra = power_t[:, :, torch.as_tensor(fov, device=device)].amax(dim=0).cpu().numpy()
    timings["seconds_azimuth_fft"] = time.perf_counter() - t

    # range-Doppler map summed over the virtual channels (TI's detection matrix)
    rd = (X.real**2 + X.imag**2).sum(dim=(1, 2)).cpu().numpy().astype(np.float64).T  # (N, D)
    rd_noise = cell_noise * nt * nr

    t = time.perf_counter()
    near = np.arange(n) * radar.range_resolution_m < sig.min_range_m
    corr_r = cfar.power_correlation(front.w_r**2, n)
    if sig.cfar_domain == "range-doppler":
        corr_d = cfar.power_correlation(front.w_d**2, n_dop)
        det, design = _detect_range_doppler(rd + (rd_noise if noise_free else 0.0), radar,
                                            corr_r, corr_d, nt * nr)
        det &= ~near[:, None]
        ri, di = np.nonzero(det)
        di, ri, ai, ei = _angles_at(X, grid, w_a, di, ri, radar)
    else:
        power = power_t.cpu().numpy().astype(np.float64)
        di, ri, ai, design = _detect_range_azimuth(
            power + (noise_az if noise_free else 0.0), radar, corr_r, fov, near, front.w_d,
            grid, w_a)
        ei = _elevation_bins(X, grid, di, ri, ai, radar)
    timings["seconds_cfar_and_angles"] = time.perf_counter() - t

    # points
    t = time.perf_counter()

    def logp_at(d, r, a):  # log power of the azimuth map at (Doppler, range, azimuth) bins
        d_t, r_t = (torch.as_tensor(d % n_dop, device=device),
                    torch.as_tensor(r % n, device=device))
        a_t = torch.as_tensor(a % n_az, device=device)
        if power_t is not None:
            cells = power_t[d_t, r_t, a_t]
        else:  # only these cells' spectra (K, A), each as the map would have it
            rows = _azimuth_power(torch, xc[d_t, :, r_t][:, :, None], row_mat, n_az)[:, 0]
            cells = rows[torch.arange(len(a_t), device=device), a_t]
        return np.log(np.maximum(cells.cpu().numpy().astype(np.float64), 1e-300))

    n_el_fft = sig.elevation_fft_size
    sin_el = (ei - n_el_fft // 2) * 2.0 / n_el_fft
    lp0 = logp_at(di, ri, ai)
    peak_w = np.exp(lp0)
    u_det = u[ai]
    rng = ri * radar.range_resolution_m
    rdot = ((di - n_dop // 2) / (n_dop * front.t_loop_s) * 0.5 * radar.wavelength_m
            if n_dop > 1 else np.zeros(len(di)))
    if sig.interpolate and len(di):
        dr, inc_r = cfar.parabolic_peak(logp_at(di, ri - 1, ai), lp0, logp_at(di, ri + 1, ai))
        da, inc_a = cfar.parabolic_peak(logp_at(di, ri, ai - 1), lp0, logp_at(di, ri, ai + 1))
        peak_w = np.exp(lp0 + inc_r + inc_a)
        u_det = np.clip(u_det + da * 2.0 / n_az, -1.0, 1.0)
        if n_dop > 1:
            dd, _ = cfar.parabolic_peak(logp_at(di - 1, ri, ai), lp0, logp_at(di + 1, ri, ai))
            rdot = rdot + dd / (n_dop * front.t_loop_s) * 0.5 * radar.wavelength_m
        sin_el = _refine_elevation(X, grid, di, ri, u_det, ei, radar)
        # range: bin spacing c f_adc / (2 S N) = c / 2B; minus the range-Doppler coupling
        # 2 rdot (f_s + B) / c of the beat frequency (fmcw module doc) expressed in range
        rng = ((ri + dr) * radar.range_resolution_m
               - rdot * (radar.start_frequency_hz + radar.bandwidth_hz) / radar.slope_hz_per_s)
    intensity_db = 10.0 * np.log10(4.0 * math.pi * np.maximum(peak_w, 1e-300) * to_a2)
    keep = (np.abs(u_det) <= gate_az + 1e-12) & (np.abs(sin_el) <= gate_el + 1e-12)
    y = rng * u_det
    z = rng * sin_el
    x_fwd = np.sqrt(np.maximum(rng**2 - y**2 - z**2, 0.0))
    points = np.column_stack([x_fwd, y, z, intensity_db, rdot])[keep].astype(np.float32)
    order = np.argsort(-points[:, 3], kind="stable")
    points = points[order]
    if sig.max_points is not None:
        points = points[: sig.max_points]
    timings["seconds_points"] = time.perf_counter() - t

    ra_db = None if ra is None else (10.0 * np.log10(
        4.0 * math.pi * np.maximum(ra.astype(np.float64), 1e-300) * to_a2)).astype(np.float32)
    stats = {
        **timings,
        **design,
        "n_detections": int(len(points)),
        "noise_floor_db": noise_floor_db,
        "noise_per_cell_w": noise_az,
        "coherent_gain": float(gain),
        "cfar_on_expected_power": bool(noise_free),
        "n_azimuth_positions": grid.n_row_positions,
        "n_doppler_bins": n_dop,
    }
    return ProcessingResult(
        points=points,
        range_m=(np.arange(n) * radar.range_resolution_m).astype(np.float32),
        azimuth_sin=u[fov].astype(np.float32),
        range_azimuth_db=ra_db,
        range_doppler_db=(10.0 * np.log10(np.maximum(rd, 1e-300))).astype(np.float32),
        noise_floor_db=noise_floor_db,
        stats=stats,
        range_doppler_cube=X if keep_cube else None,
    )


# -- detection ----------------------------------------------------------------------------
def _detect_range_doppler(rd: np.ndarray, radar: RadarConfig, corr_r: np.ndarray,
                          corr_d: np.ndarray, looks: int) -> tuple[np.ndarray, dict[str, Any]]:
    """TI's dual-pass CFAR on the (N, D) integrated map (module doc, stage 4)."""
    sig = radar.signal
    (g_r, g_d), (t_r, t_d) = sig.cfar_guard_cells, sig.cfar_training_cells
    thr = sig.cfar_threshold or (None, None)
    n_range, n_dop = rd.shape
    n_eff_r = cfar.effective_side_cells(t_r, corr_r) if sig.cfar_kind == "caso" else (
        2 * cfar.effective_side_cells(t_r, corr_r))
    alpha_r, pfa_r = _threshold(sig.cfar_kind, thr[0], n_eff_r, looks, radar)
    det, _ = cfar.cfar_1d(rd, axis=0, kind=sig.cfar_kind, guard=g_r, train=t_r, alpha=alpha_r,
                          edges="ti", discard=sig.cfar_discard_range_bins,
                          rank=sig.cfar_os_rank)
    design: dict[str, Any] = {"cfar_looks": looks, "cfar_alpha_range_db":
                              10.0 * math.log10(alpha_r), "cfar_design_pfa_range": pfa_r,
                              "cfar_n_eff_range": n_eff_r}
    if n_dop > 1:
        if n_dop < 2 * (g_d + t_d) + 1:
            raise ValueError(f"the Doppler CFAR window ({2 * (g_d + t_d) + 1} cells) does not fit "
                             f"the {n_dop} Doppler bins; reduce cfar_guard_cells / "
                             "cfar_training_cells or use more chirps")
        n_eff_d = cfar.effective_side_cells(t_d, corr_d) * (1 if sig.cfar_kind == "caso" else 2)
        alpha_d, pfa_d = _threshold(sig.cfar_kind, thr[1], n_eff_d, looks, radar)
        det_d, _ = cfar.cfar_1d(rd, axis=1, kind=sig.cfar_kind, guard=g_d, train=t_d,
                                alpha=alpha_d, edges="wrap", rank=sig.cfar_os_rank)
        det &= det_d
        design.update(cfar_alpha_doppler_db=10.0 * math.log10(alpha_d),
                      cfar_design_pfa_doppler=pfa_d, cfar_n_eff_doppler=n_eff_d)
    if sig.peak_grouping:
        det &= cfar.is_local_max(rd, det)
    return det, design


def _detect_range_azimuth(power: np.ndarray, radar: RadarConfig, corr_r: np.ndarray,
                          fov: np.ndarray, near: np.ndarray, w_d: np.ndarray,
                          grid: VirtualGrid, w_a: np.ndarray):
    """2-D CA/OS CFAR on each Doppler bin's range-azimuth map (module doc, stage 4)."""
    sig = radar.signal
    n_dop, _, n_az = power.shape
    az_profile = w_a**2 * grid.noise_gain[:, grid.row]
    corr_a = cfar.power_correlation(az_profile, n_az)
    offsets = cfar.training_offsets(sig.cfar_guard_cells, sig.cfar_training_cells)
    if sig.cfar_kind == "os":
        n_eff = cfar.effective_training_cells_os(offsets, corr_r, corr_a, sig.cfar_os_rank)
    else:
        n_eff = cfar.effective_training_cells(offsets, corr_r, corr_a)
    given = sig.cfar_threshold[0] if sig.cfar_threshold else None
    alpha, pfa = _threshold(sig.cfar_kind, given, n_eff, 1, radar)
    size = (3 if n_dop > 1 else 1, 3, 3)
    if sig.peak_grouping:
        cand = power >= ndimage.maximum_filter(power, size=size, mode="wrap")
    else:
        cand = np.ones(power.shape, bool)
    cand &= fov[None, None, :] & ~near[None, :, None]
    if n_dop > 1:  # Doppler sidelobes of a strong echo are not targets
        cand &= power >= power.max(axis=0, keepdims=True) * 10.0 ** (
            -sig.doppler_sidelobe_db / 10.0)
    det = cfar.cfar_detect(power, kind=sig.cfar_kind, guard=sig.cfar_guard_cells,
                           train=sig.cfar_training_cells, alpha=alpha, rank=sig.cfar_os_rank,
                           candidates=cand)
    di, ri, ai = np.nonzero(det)
    design = {"cfar_looks": 1, "cfar_alpha_db": 10.0 * math.log10(alpha),
              "cfar_design_pfa": pfa, "cfar_n_train": int(len(offsets)), "cfar_n_eff": n_eff}
    return di, ri, ai, design


# -- angles -------------------------------------------------------------------------------
def _grid_values(X, grid: VirtualGrid, di: np.ndarray, ri: np.ndarray):
    """(K, n_az, n_el) complex64 torch — the virtual grid of each detection's channels."""
    import torch

    nt, nr = X.shape[1], X.shape[2]
    data = X[torch.as_tensor(di, device=X.device), :, :, torch.as_tensor(ri, device=X.device)]
    w = torch.as_tensor(grid.weights.reshape(nt * nr, -1), device=X.device,
                        dtype=torch.complex64)
    return (data.reshape(len(di), nt * nr) @ w).reshape(len(di), grid.n_azimuth,
                                                         grid.n_elevation)


def _angles_at(X, grid: VirtualGrid, w_a: np.ndarray, di: np.ndarray, ri: np.ndarray,
               radar: RadarConfig):
    """TI's DOA at each range-Doppler detection: azimuth peaks within ``angle_sidelobe_db``,
    per azimuth peak the elevation peaks within ``elevation_sidelobe_db`` (module doc, stage
    5). Returns (doppler, range, azimuth, elevation) bin indices, one row per point."""
    import torch

    sig = radar.signal
    e = np.zeros(0, np.int64)
    if len(di) == 0:
        return e, e, e, e
    gamma = 10.0 ** (sig.angle_peak_hysteresis_db / 10.0)
    w_t = torch.as_tensor(w_a, device=X.device, dtype=torch.float32)[None, :, None]
    vals = _grid_values(X, grid, di, ri) * w_t                             # (K, A_pos, E_pos)
    az = _spectrum_bins(vals.transpose(1, 2), sig.azimuth_fft_size)        # (K, E_pos, A)
    mag = az[:, grid.row, :].abs().cpu().numpy()
    k_idx, a_idx = np.nonzero(cfar.hysteresis_peaks(mag, gamma=gamma,
                                                    sidelobe_db=sig.angle_sidelobe_db))
    col = az[torch.as_tensor(k_idx, device=X.device), :,
             torch.as_tensor(a_idx, device=X.device)]                      # (P, E_pos)
    el = _spectrum_bins(col, sig.elevation_fft_size).abs().cpu().numpy()
    p_idx, e_idx = np.nonzero(cfar.hysteresis_peaks(el, gamma=gamma,
                                                    sidelobe_db=sig.elevation_sidelobe_db))
    k_idx, a_idx = k_idx[p_idx], a_idx[p_idx]
    return di[k_idx], ri[k_idx], a_idx, e_idx


def _elevation_bins(X, grid: VirtualGrid, di: np.ndarray, ri: np.ndarray, ai: np.ndarray,
                    radar: RadarConfig) -> np.ndarray:
    """Elevation FFT bin of the maximum at each (detection, azimuth bin) (range-azimuth
    domain: one elevation per point)."""
    import torch

    if len(di) == 0:
        return np.zeros(0, np.int64)
    sig = radar.signal
    az = _spectrum_bins(_grid_values(X, grid, di, ri).transpose(1, 2), sig.azimuth_fft_size)
    col = az[torch.arange(len(di), device=X.device), :, torch.as_tensor(ai, device=X.device)]
    el = _spectrum_bins(col, sig.elevation_fft_size).abs()
    return el.argmax(dim=1).cpu().numpy()


def _refine_elevation(X, grid: VirtualGrid, di: np.ndarray, ri: np.ndarray, u: np.ndarray,
                      ei: np.ndarray, radar: RadarConfig) -> np.ndarray:
    """sin(elevation) refined by a parabola on the elevation spectrum at the refined azimuth
    ``u`` (interpolate: true)."""
    import torch

    sig = radar.signal
    n_el = sig.elevation_fft_size
    if len(di) == 0:
        return np.zeros(0)
    vals = _grid_values(X, grid, di, ri)                                   # (K, A_pos, E_pos)
    steer = torch.as_tensor(np.exp(1j * math.pi * np.arange(grid.n_azimuth)[None, :]
                                   * u[:, None]), device=X.device, dtype=torch.complex64)
    col = torch.einsum("kae,ka->ke", vals, steer)
    el = _spectrum_bins(col, n_el).abs().square().cpu().numpy().astype(np.float64)
    lp = np.log(np.maximum(el, 1e-300))
    k = np.arange(len(di))
    delta, _ = cfar.parabolic_peak(lp[k, (ei - 1) % n_el], lp[k, ei], lp[k, (ei + 1) % n_el])
    return np.clip((ei - n_el // 2 + delta) * 2.0 / n_el, -1.0, 1.0)
