"""The reference radar's processing chain: IF samples -> point cloud (TI's cascade chain).

Stages, as in TI's cascade MIMO chain (TIDEP-01012 "Imaging radar using cascaded mmWave
sensor reference design", §2.4 signal chain) and TI SWRA553 (FFT sections):

1. **Range FFT** per chirp and channel with ``signal.range_window`` (bin ``k`` <-> beat
   frequency ``k f_adc / N``, range ``k c / (2 B)``; SWRA553 range-resolution section).
2. **Doppler FFT** across chirps with ``signal.doppler_window`` (``doppler: full``; bin ``d``
   <-> ``f_D = d / (N_chirps T_loop)``, radial velocity ``f_D lambda / 2``, positive =
   receding; ``T_loop = N_tx T_c``). ``doppler: integrated`` has one (zero-Doppler) bin.
3. **TDM phase compensation**: TX ``t`` fires ``s_t T_c`` after the loop start, so a target
   of Doppler ``f_D`` adds ``2 pi f_D s_t T_c`` to its channels; each Doppler bin's channels
   are multiplied by ``exp(-j 2 pi f_D s_t T_c)`` (TIDEP-01012 §2.4, "Doppler compensation";
   Bechter, Roos & Waldschmidt, IEEE MWCL 27(11), 2017, eq. (4)).
4. **Virtual array**: the azimuth row is the virtual elevation with the most distinct azimuth
   positions (86 for the cascade); duplicate positions are averaged (same signal, noise
   variance / n_dup). **Azimuth beamforming** by a zero-padded FFT of ``azimuth_fft_size``
   over the row with ``signal.azimuth_window``: bins are uniform in ``u = sin(az) cos(el)``
   (``u_m = 2 m / N_fft``), so the beamwidth grows as ``1 / cos(az)``; only ``|u| <=
   sin(azimuth_fov / 2)`` is reported. The beamformer is matched to the IF phase convention of
   :mod:`sim2radar.radar.fmcw` (``Z(u) = sum_v x_v exp(+j pi v u)``, ``v`` in lambda/2 units):
   ``+u`` is left (``+y``).
5. **CFAR** (``cfar_kind``: CA or OS) over a 2-D plane (``cfar_domain``): ``range-azimuth``
   (each Doppler bin's ``|Z|^2`` map) or ``range-doppler`` (``sum_v |X_v|^2`` over all virtual
   channels, TI's detection matrix, then azimuth peaks within ``angle_sidelobe_db`` of the
   strongest at each detection). Training cells: a rectangle of ``guard + training`` cells each
   side minus the guard rectangle, wrapped circularly (the DFT axes are periodic). Thresholds
   from the design ``cfar_pfa``:

   * CA (Richards, *Fundamentals of Radar Signal Processing*, 2nd ed., §6.5):
     ``alpha = N (P_fa^(-1/N) - 1)`` for ``N`` independent exponential training cells; with
     ``K`` non-coherently summed looks per cell (range-doppler) the cell and training sums are
     Gamma distributed and ``P_fa = I_{1-b}(N K, K)`` with ``b = alpha / (N + alpha)`` (the
     ratio of Gamma variables is Beta; Richards §6.5 generalised), solved with scipy.
   * OS (Rohling, IEEE TAES 19(4), 608-621, 1983, eq. (19)): ``P_fa = k C(N, k) Gamma(k)
     Gamma(alpha + N - k + 1) / Gamma(alpha + N + 1)`` with the ``k``-th smallest training
     cell, ``k = ceil(rank N)``; for ``K > 1`` looks the same expectation is integrated
     numerically. ``alpha`` is found with :func:`scipy.optimize.brentq`.

   Neighbouring cells of a windowed, zero-padded FFT are correlated, which makes fewer
   *independent* training cells than ``N``. The power correlation of two cells is
   ``|rho|^2`` (Gaussian noise), ``rho`` the normalised DFT of the noise's window-squared
   profile along each axis; the training sum's variance then matches a Gamma sum of
   ``N_eff = N^2 / sum_ij |rho_ij|^2`` independent cells (Satterthwaite's moment matching,
   Biometrics Bull. 2(6), 1946), and ``N_eff`` (with ``k_eff = k N_eff / N`` for OS) replaces
   ``N`` in the formulas above.
6. **Peak grouping** (local maxima over 3x3 (x3 with Doppler) cells; with Doppler, only bins
   within ``doppler_sidelobe_db`` of their range-azimuth cell's strongest) and **sub-bin
   interpolation**: a parabola through the log power of the peak and its two neighbours in
   range, azimuth and Doppler (Gaussian interpolation; Gasior & Gonzalez, CERN-AB-2004-023,
   eq. (7)) gives the position and the peak power.
7. **Elevation** at each detection: a beamforming scan over *all* virtual channels (positions
   ``tx + rx`` of :func:`~sim2radar.radar.fmcw.element_positions_m`) at the detection's ``u``,
   ``elevation_step_deg`` steps over the elevation FOV, parabolic refinement.

Intensity scale
---------------
A point's ``intensity_db = 10 log10(4 pi |a|^2)``, the ray tracer's scale
(:mod:`sim2radar.radar.returns`), with ``|a|^2 = P_peak / (K_echo G^2)``: ``P_peak`` the
interpolated peak power of the azimuth map [W per sample^2], ``K_echo`` =
:func:`~sim2radar.radar.link_budget.echo_power_scale_w` and ``G = (sum w_range) (sum
w_doppler) (sum w_azimuth over filled positions)`` the coherent gain of the three FFTs. A point
target of RCS ``sigma`` at boresight thus reads ``sigma [dBsm] - 40 log10 r``; off boresight the
element patterns lower it (the real radar's behaviour, which the ray tracer lacks). The thermal
noise per cell on the same scale is ``stats["noise_floor_db"]``; ``intensity_db -
noise_floor_db`` is the detection's SNR.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any

import numpy as np
from scipy import integrate, ndimage, optimize, special, stats

from sim2radar.radar import link_budget
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.fmcw import IFCube, element_positions_m, tx_slots, window_weights

__all__ = [
    "ProcessingResult",
    "azimuth_row",
    "cfar_detect",
    "cfar_threshold_factor",
    "effective_training_cells",
    "effective_training_cells_os",
    "process_if",
    "training_offsets",
]


# -- CFAR ---------------------------------------------------------------------------------
def training_offsets(guard: tuple[int, int], train: tuple[int, int]) -> np.ndarray:
    """(N, 2) int — offsets of the training cells: the ``(g + t)`` rectangle minus the ``g``
    rectangle (each side, per axis)."""
    (g0, g1), (t0, t1) = guard, train
    a = np.arange(-(g0 + t0), g0 + t0 + 1)
    b = np.arange(-(g1 + t1), g1 + t1 + 1)
    aa, bb = np.meshgrid(a, b, indexing="ij")
    keep = ~((np.abs(aa) <= g0) & (np.abs(bb) <= g1))
    return np.column_stack([aa[keep], bb[keep]])


def _power_correlation(profile: np.ndarray, n_fft: int) -> np.ndarray:
    """(n_fft,) — ``|rho(lag)|^2`` of DFT bins of noise with variance profile ``profile``."""
    rho = np.fft.fft(profile, n_fft) / profile.sum()
    return np.abs(rho) ** 2


def effective_training_cells(offsets: np.ndarray, corr0: np.ndarray, corr1: np.ndarray) -> float:
    """``N_eff = N^2 / sum_ij |rho_0(di)|^2 |rho_1(dj)|^2`` (module doc, step 5)."""
    d0 = offsets[:, None, 0] - offsets[None, :, 0]
    d1 = offsets[:, None, 1] - offsets[None, :, 1]
    var = (corr0[d0 % len(corr0)] * corr1[d1 % len(corr1)]).sum()
    return float(len(offsets) ** 2 / var)


def effective_training_cells_os(offsets: np.ndarray, corr0: np.ndarray, corr1: np.ndarray,
                                rank: float) -> float:
    """Independent-cell equivalent of correlated training cells for an OS-CFAR of ``rank``.

    The sample ``p``-quantile's variance is ``sum_ij Cov(1{X_i <= q}, 1{X_j <= q}) / (N f(q))^2``
    (Bahadur, Ann. Math. Statist. 37(3), 1966), so ``N_os = N^2 p (1 - p) / sum_ij Cov_ij``.
    Two square-law cells with power correlation ``rho`` follow Kibble's bivariate exponential
    (Kibble, Sankhya 5(2), 1941), whose Laguerre series gives ``Cov = sum_{k>=1} rho^k I_k^2``,
    ``I_k = q e^{-q} L^{(1)}_{k-1}(q) / k``, ``q = -ln(1 - p)`` (single look)."""
    p = float(rank)
    q = -math.log(max(1.0 - p, 1e-12))
    k = np.arange(1, 161)
    i_k = q * math.exp(-q) * special.eval_genlaguerre(k - 1, 1, q) / k
    d0 = offsets[:, None, 0] - offsets[None, :, 0]
    d1 = offsets[:, None, 1] - offsets[None, :, 1]
    rho = corr0[d0 % len(corr0)] * corr1[d1 % len(corr1)]
    uniq, inv = np.unique(np.round(rho, 12), return_inverse=True)
    cov_u = (np.clip(uniq, 0.0, 1.0)[:, None] ** k[None, :] * i_k[None, :] ** 2).sum(axis=1)
    cov = cov_u[inv.reshape(rho.shape)]
    np.fill_diagonal(cov, p * (1.0 - p))
    return float(len(offsets) ** 2 * p * (1.0 - p) / cov.sum())


@functools.lru_cache(maxsize=256)
def cfar_threshold_factor(kind: str, n_train: float, pfa: float, *, looks: int = 1,
                          rank: float = 0.75) -> float:
    """CFAR scale ``alpha`` for a design false-alarm rate (module doc, step 5).

    Parameters
    ----------
    kind : ``"ca"`` or ``"os"``.
    n_train : float — (effective) number of independent training cells.
    pfa : float — design false-alarm probability per cell.
    looks : int — non-coherently summed looks per cell (1: square-law single look).
    rank : float — OS: the order statistic as a fraction of the training cells.

    Returns
    -------
    alpha : float — detect when ``P > alpha * mean(training)`` (CA) or ``P > alpha *
        (k-th smallest training cell)`` (OS).
    """
    n, k_looks = float(n_train), int(looks)
    if kind == "ca":
        # P(X > alpha/N S) with X ~ Gamma(K), S ~ Gamma(N K): X / (X + S) ~ Beta(K, N K)
        b = stats.beta.isf(pfa, k_looks, n * k_looks)
        return float(n * b / (1.0 - b))
    if kind != "os":
        raise ValueError(f"unknown CFAR kind {kind!r}; known: 'ca', 'os'")
    k = max(1.0, min(n, math.ceil(rank * n - 1e-9) if float(n).is_integer() else rank * n))

    if k_looks == 1:  # Rohling 1983, eq. (19), in log-gamma form (real N, k allowed)
        def log_pfa(t: float) -> float:
            return (special.gammaln(n + 1) - special.gammaln(n - k + 1)
                    + special.gammaln(t + n - k + 1) - special.gammaln(t + n + 1))
    else:
        def log_pfa(t: float) -> float:
            def f(b: float) -> float:
                z = stats.gamma.ppf(b, k_looks)
                return stats.gamma.sf(t * z, k_looks) * stats.beta.pdf(b, k, n - k + 1)

            val, _ = integrate.quad(f, 0.0, 1.0, limit=200, epsabs=0.0, epsrel=1e-8)
            return math.log(max(val, 1e-300))

    target = math.log(pfa)
    hi = 1.0
    while log_pfa(hi) > target:
        hi *= 2.0
        if hi > 1e9:
            raise ValueError(f"OS-CFAR: no threshold reaches pfa={pfa} with N={n}, k={k}")
    return float(optimize.brentq(lambda t: log_pfa(t) - target, 0.0, hi, xtol=1e-10))


def cfar_detect(power: np.ndarray, *, kind: str, guard: tuple[int, int],
                train: tuple[int, int], alpha: float, rank: float = 0.75,
                candidates: np.ndarray | None = None) -> np.ndarray:
    """Boolean detection mask of a 2-D power plane (or a stack of planes, leading axes).

    Parameters
    ----------
    power : (..., n0, n1) float — square-law cells; both axes wrap circularly.
    kind, guard, train, alpha, rank : see :func:`cfar_threshold_factor`.
    candidates : same shape, bool, optional — only these cells are tested (e.g. local maxima).

    Returns
    -------
    (..., n0, n1) bool
    """
    p = np.asarray(power, dtype=np.float64)
    n0, n1 = p.shape[-2:]
    (g0, g1), (t0, t1) = guard, train
    if 2 * (g0 + t0) + 1 > n0 or 2 * (g1 + t1) + 1 > n1:
        raise ValueError(f"CFAR window {2 * (g0 + t0) + 1} x {2 * (g1 + t1) + 1} cells does not "
                         f"fit the {n0} x {n1} plane; reduce cfar_guard_cells / "
                         "cfar_training_cells")
    cand = np.ones(p.shape, bool) if candidates is None else np.asarray(candidates, bool)
    offsets = training_offsets(guard, train)
    n_train = len(offsets)
    out = np.zeros(p.shape, dtype=bool)
    if kind == "ca":
        lead = (1,) * (p.ndim - 2)

        def box(size0: int, size1: int) -> np.ndarray:
            return ndimage.uniform_filter(p, size=lead + (size0, size1), mode="wrap") * (
                size0 * size1)

        s = box(2 * (g0 + t0) + 1, 2 * (g1 + t1) + 1) - box(2 * g0 + 1, 2 * g1 + 1)
        out = cand & (p > alpha * s / n_train)
        return out
    if kind != "os":
        raise ValueError(f"unknown CFAR kind {kind!r}; known: 'ca', 'os'")
    k = max(1, min(n_train, math.ceil(rank * n_train - 1e-9)))
    idx = np.nonzero(cand)
    flat_p = p.reshape(-1, n0, n1)
    lead_idx = (np.ravel_multi_index(idx[:-2], p.shape[:-2]) if p.ndim > 2
                else np.zeros(len(idx[0]), np.int64))
    i0, i1 = idx[-2], idx[-1]
    det = np.zeros(len(i0), bool)
    step = max(1, (1 << 22) // n_train)
    for s in range(0, len(i0), step):
        sl = slice(s, s + step)
        r0 = (i0[sl, None] + offsets[None, :, 0]) % n0
        r1 = (i1[sl, None] + offsets[None, :, 1]) % n1
        vals = flat_p[lead_idx[sl, None], r0, r1].astype(np.float32)
        kth = np.partition(vals, k - 1, axis=1)[:, k - 1]
        det[sl] = flat_p[lead_idx[sl], i0[sl], i1[sl]] > alpha * kth
    out[tuple(ix[det] for ix in idx)] = True
    return out


# -- virtual array ------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class AzimuthRow:
    """The virtual azimuth row used for azimuth beamforming.

    Attributes
    ----------
    channels : (C_row,) int — flat virtual-channel indices ``t * N_rx + r`` in the row.
    position : (C_row,) int — each channel's azimuth position [lambda/2] from the row's start.
    n_dup : (n_pos,) int — channels per position (0 = gap).
    averaging : (C_row, n_pos) float64 — channel -> position averaging matrix [-].
    """

    channels: np.ndarray
    position: np.ndarray
    n_dup: np.ndarray
    averaging: np.ndarray

    @property
    def n_positions(self) -> int:
        return int(np.count_nonzero(self.n_dup))


def azimuth_row(radar: RadarConfig) -> AzimuthRow:
    """The virtual elevation with the most distinct azimuth positions, duplicates averaged."""
    v = np.round(radar.virtual_array_half_wl, 6)
    best = None
    for el in np.unique(v[:, 1]):
        ch = np.nonzero(v[:, 1] == el)[0]
        key = (len(np.unique(v[ch, 0])), len(ch))
        if best is None or key > best[0]:
            best = (key, ch)
    ch = best[1]
    az = v[ch, 0]
    if not np.allclose(az, np.round(az)):
        raise ValueError("azimuth beamforming by FFT needs virtual azimuth positions on the "
                         "lambda/2 grid")
    pos = (np.round(az) - np.round(az).min()).astype(np.int64)
    n_pos = int(pos.max()) + 1
    if n_pos > radar.signal.azimuth_fft_size:
        raise ValueError(f"signal.azimuth_fft_size={radar.signal.azimuth_fft_size} is shorter "
                         f"than the {n_pos}-position azimuth row")
    n_dup = np.bincount(pos, minlength=n_pos)
    avg = np.zeros((len(ch), n_pos))
    avg[np.arange(len(ch)), pos] = 1.0 / n_dup[pos]
    return AzimuthRow(channels=ch, position=pos, n_dup=n_dup, averaging=avg)


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
    range_azimuth_db : (n_range, n_az) float32 — max over Doppler of the azimuth map, on the
        intensity scale [dB].
    noise_floor_db : float — thermal noise per range-azimuth cell, intensity scale [dB].
    stats : dict — seconds per stage, counts, CFAR design.
    range_doppler_cube : torch tensor or None — (n_doppler, N_tx, N_rx, n_range) complex64
        after range/Doppler FFT and TDM compensation (``keep_cube=True``).
    """

    points: np.ndarray
    range_m: np.ndarray
    azimuth_sin: np.ndarray
    range_azimuth_db: np.ndarray
    noise_floor_db: float
    stats: dict[str, Any]
    range_doppler_cube: Any = None


def _parabolic(lm: np.ndarray, l0: np.ndarray, lp: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offset [bins] and log-peak increment of a parabola through three log powers."""
    den = lm - 2.0 * l0 + lp
    ok = den < 0
    delta = np.where(ok, 0.5 * (lm - lp) / np.where(ok, den, -1.0), 0.0)
    delta = np.clip(delta, -0.5, 0.5)
    return delta, 0.25 * (lp - lm) * delta


def process_if(cube: IFCube, radar: RadarConfig, *, noise_free: bool = False,
               keep_cube: bool = False) -> ProcessingResult:
    """Run the chain (module doc) on synthesised IF samples.

    Parameters
    ----------
    cube : IFCube — from :func:`sim2radar.radar.fmcw.synthesize_if`.
    radar : RadarConfig — the same config the cube was synthesised with.
    noise_free : bool — the cube has no noise: CFAR then runs on the *expected* power (the
        map plus the known noise per cell), so detections are deterministic.
    keep_cube : bool — return the range-Doppler cube.
    """
    import torch

    sig = radar.signal
    x = cube.samples
    device = x.device
    timings: dict[str, float] = {}
    t = time.perf_counter()
    n_slow, nt, nr, n = x.shape
    w_r = window_weights(sig.range_window, n)
    w_d = window_weights(sig.doppler_window, radar.n_chirps)
    X = torch.fft.fft(x * torch.as_tensor(w_r, device=device, dtype=torch.float32), dim=-1)
    timings["seconds_range_fft"] = time.perf_counter() - t

    t = time.perf_counter()
    t_loop = radar.n_tx * radar.chirp_period_s
    if cube.doppler_integrated:
        n_dop = 1
        f_d = np.zeros(1)
    else:
        n_dop = n_slow
        X = torch.fft.fftshift(torch.fft.fft(
            X * torch.as_tensor(w_d, device=device, dtype=torch.float32)[:, None, None, None],
            dim=0), dim=0)
        f_d = (np.arange(n_dop) - n_dop // 2) / (n_dop * t_loop)            # [Hz]
        slot_s = tx_slots(radar) * radar.chirp_period_s                     # [s]
        comp = np.exp(-2j * np.pi * f_d[:, None] * slot_s[None, :])        # (D, T)
        X = X * torch.as_tensor(comp, device=device, dtype=torch.complex64)[:, :, None, None]
    timings["seconds_doppler_fft"] = time.perf_counter() - t

    # azimuth beamforming over the virtual row
    t = time.perf_counter()
    row = azimuth_row(radar)
    n_az = sig.azimuth_fft_size
    Xc = X.reshape(n_dop, nt * nr, n)
    w_a = np.zeros(len(row.n_dup))
    filled = row.n_dup > 0
    w_a[filled] = window_weights(sig.azimuth_window, len(row.n_dup))[filled]
    avg = torch.as_tensor(row.averaging * w_a[row.position][:, None], device=device,
                          dtype=torch.complex64)
    Y = torch.einsum("dcn,cp->dnp", Xc[:, torch.as_tensor(row.channels, device=device)], avg)
    Z = torch.fft.fftshift(torch.fft.ifft(Y, n=n_az, dim=-1) * n_az, dim=-1)  # (D, N, A)
    power = (Z.real**2 + Z.imag**2).cpu().numpy().astype(np.float64)
    u = (np.arange(n_az) - n_az // 2) * 2.0 / n_az
    fov = np.abs(u) <= math.sin(0.5 * radar.azimuth_fov_rad) + 1e-12
    timings["seconds_azimuth_fft"] = time.perf_counter() - t

    # scales
    k_echo = link_budget.echo_power_scale_w(radar)
    gain = w_r.sum() * w_d.sum() * w_a.sum()
    to_a2 = 1.0 / (k_echo * gain**2)
    doppler_noise = 1.0 if cube.doppler_integrated else float(np.sum(w_d**2))
    noise_cell = (cube.noise_power_w * np.sum(w_r**2) * doppler_noise
                  * float(np.sum(w_a[filled] ** 2 / row.n_dup[filled])))
    noise_floor_db = 10.0 * math.log10(4.0 * math.pi * noise_cell * to_a2)

    # CFAR
    t = time.perf_counter()
    corr_r = _power_correlation(w_r**2, n)
    corr_d = _power_correlation(w_d**2, n_dop) if n_dop > 1 else np.ones(1)
    az_profile = np.zeros(len(row.n_dup))
    az_profile[filled] = w_a[filled] ** 2 / row.n_dup[filled]
    corr_a = _power_correlation(az_profile, n_az)
    offsets = training_offsets(sig.cfar_guard_cells, sig.cfar_training_cells)
    if sig.cfar_domain == "range-azimuth":
        plane = power + (noise_cell if noise_free else 0.0)                 # (D, N, A)
        looks, n_eff = 1, effective_training_cells(offsets, corr_r, corr_a)
        size = (3 if n_dop > 1 else 1, 3, 3)
    else:
        if n_dop < 2 * (sig.cfar_guard_cells[1] + sig.cfar_training_cells[1]) + 1:
            raise ValueError("cfar_domain 'range-doppler' needs doppler: full and enough chirps "
                             "for the CFAR window along Doppler")
        rd = (X.real**2 + X.imag**2).sum(dim=(1, 2)).cpu().numpy().astype(np.float64)  # (D, N)
        rd_noise = cube.noise_power_w * np.sum(w_r**2) * doppler_noise * nt * nr
        plane = (rd + (rd_noise if noise_free else 0.0)).T                  # (N, D)
        looks, n_eff = nt * nr, effective_training_cells(offsets, corr_r, corr_d)
        size = (3, 3)
    if sig.cfar_kind == "os" and looks == 1:
        corr1 = corr_a if sig.cfar_domain == "range-azimuth" else corr_d
        n_eff = effective_training_cells_os(offsets, corr_r, corr1, sig.cfar_os_rank)
    alpha = cfar_threshold_factor(sig.cfar_kind, n_eff, sig.cfar_pfa, looks=looks,
                                  rank=sig.cfar_os_rank)
    if sig.peak_grouping:
        cand = plane >= ndimage.maximum_filter(plane, size=size, mode="wrap")
    else:
        cand = np.ones(plane.shape, bool)
    near = np.arange(n) * radar.range_resolution_m < sig.min_range_m
    if sig.cfar_domain == "range-azimuth":
        cand &= fov[None, None, :] & ~near[None, :, None]
        if n_dop > 1:  # Doppler sidelobes of a strong echo are not targets
            cand &= plane >= plane.max(axis=0, keepdims=True) * 10.0 ** (
                -sig.doppler_sidelobe_db / 10.0)
    else:
        cand &= ~near[:, None]
    det = cfar_detect(plane, kind=sig.cfar_kind, guard=sig.cfar_guard_cells,
                      train=sig.cfar_training_cells, alpha=alpha, rank=sig.cfar_os_rank,
                      candidates=cand)
    if sig.cfar_domain == "range-azimuth":
        di, ri, ai = np.nonzero(det)
    else:
        ri_rd, di_rd = np.nonzero(det)
        di, ri, ai = _azimuth_peaks(power, di_rd, ri_rd, fov, sig.angle_sidelobe_db)
    timings["seconds_cfar"] = time.perf_counter() - t

    # points
    t = time.perf_counter()
    logp = np.log(np.maximum(power, 1e-300))
    dr, inc_r = _parabolic(logp[di, (ri - 1) % n, ai], logp[di, ri, ai], logp[di, (ri + 1) % n, ai])
    da, inc_a = _parabolic(logp[di, ri, (ai - 1) % n_az], logp[di, ri, ai],
                           logp[di, ri, (ai + 1) % n_az])
    if n_dop > 1:
        dd, _ = _parabolic(logp[(di - 1) % n_dop, ri, ai], logp[di, ri, ai],
                           logp[(di + 1) % n_dop, ri, ai])
    else:
        dd = np.zeros(len(di))
    peak_w = np.exp(logp[di, ri, ai] + inc_r + inc_a)
    intensity_db = 10.0 * np.log10(4.0 * math.pi * np.maximum(peak_w, 1e-300) * to_a2)
    rdot = (di - n_dop // 2 + dd) / (n_dop * t_loop) * 0.5 * radar.wavelength_m if n_dop > 1 \
        else np.zeros(len(di))
    # range: bin spacing c f_adc / (2 S N) = c / 2B; minus the range-Doppler coupling
    # 2 rdot (f_s + B) / c of the beat frequency (fmcw module doc) expressed in range
    rng = ((ri + dr) * radar.range_resolution_m
           - rdot * (radar.start_frequency_hz + radar.bandwidth_hz) / radar.slope_hz_per_s)
    u_det = np.clip((ai - n_az // 2 + da) * 2.0 / n_az, -1.0, 1.0)
    sin_el = _elevation(X, radar, di, ri, u_det)
    y = rng * u_det
    z = rng * sin_el
    x_fwd = np.sqrt(np.maximum(rng**2 - y**2 - z**2, 0.0))
    points = np.column_stack([x_fwd, y, z, intensity_db, rdot]).astype(np.float32)
    order = np.argsort(-points[:, 3], kind="stable")
    points = points[order]
    if sig.max_points is not None:
        points = points[: sig.max_points]
    timings["seconds_points"] = time.perf_counter() - t

    ra = power[:, :, fov].max(axis=0)
    ra_db = (10.0 * np.log10(4.0 * math.pi * np.maximum(ra, 1e-300) * to_a2)).astype(np.float32)
    stats = {
        **timings,
        "n_detections": int(len(points)),
        "noise_floor_db": noise_floor_db,
        "noise_per_cell_w": noise_cell,
        "coherent_gain": float(gain),
        "cfar_alpha_db": 10.0 * math.log10(alpha),
        "cfar_n_train": int(len(offsets)),
        "cfar_n_eff": n_eff,
        "cfar_looks": looks,
        "cfar_on_expected_power": bool(noise_free),
        "n_azimuth_positions": row.n_positions,
        "n_doppler_bins": n_dop,
    }
    return ProcessingResult(
        points=points,
        range_m=(np.arange(n) * radar.range_resolution_m).astype(np.float32),
        azimuth_sin=u[fov].astype(np.float32),
        range_azimuth_db=ra_db,
        noise_floor_db=noise_floor_db,
        stats=stats,
        range_doppler_cube=X if keep_cube else None,
    )


def _azimuth_peaks(power: np.ndarray, di: np.ndarray, ri: np.ndarray, fov: np.ndarray,
                   sidelobe_db: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Azimuth local maxima in the FOV within ``sidelobe_db`` of each detection's strongest
    (TI's multi-peak angle search)."""
    if len(di) == 0:
        e = np.zeros(0, np.int64)
        return e, e, e
    spec = power[di, ri]                                                   # (n, A)
    loc = (spec >= np.roll(spec, 1, axis=1)) & (spec >= np.roll(spec, -1, axis=1)) & fov
    masked = np.where(fov, spec, 0.0)
    top = masked.max(axis=1, keepdims=True)
    keep = loc & (spec >= top * 10.0 ** (-sidelobe_db / 10.0)) & (top > 0)
    k, a = np.nonzero(keep)
    return di[k], ri[k], a


def _elevation(X, radar: RadarConfig, di: np.ndarray, ri: np.ndarray, u: np.ndarray
               ) -> np.ndarray:
    """sin(elevation) of each detection by a beamforming scan over all virtual channels."""
    import torch

    if len(di) == 0:
        return np.zeros(0)
    tx_m, rx_m = element_positions_m(radar)
    v = (tx_m[:, None, :] + rx_m[None, :, :]).reshape(-1, 3)               # (C, 3) [m]
    k = 2.0 * math.pi / radar.wavelength_m
    half = 0.5 * radar.elevation_fov_deg
    step = radar.signal.elevation_step_deg
    el = np.deg2rad(np.arange(-half, half + 0.5 * step, step))
    if np.ptp(v[:, 2]) == 0 or len(el) < 3:
        return np.zeros(len(di))
    nt, nr = X.shape[1], X.shape[2]
    data = X[torch.as_tensor(di, device=X.device), :, :, torch.as_tensor(ri, device=X.device)]
    data = data.reshape(len(di), nt * nr).cpu().numpy().astype(np.complex128)
    data = data * np.exp(1j * k * v[None, :, 1] * u[:, None])
    steer = np.exp(1j * k * v[:, 2, None] * np.sin(el)[None, :])           # (C, n_el)
    b = np.abs(data @ steer) ** 2
    j = np.argmax(b, axis=1)
    lb = np.log(np.maximum(b, 1e-300))
    rows = np.arange(len(di))
    inner = (j > 0) & (j < len(el) - 1)
    jm, jp = np.clip(j - 1, 0, len(el) - 1), np.clip(j + 1, 0, len(el) - 1)
    delta, _ = _parabolic(lb[rows, jm], lb[rows, j], lb[rows, jp])
    phi = el[j] + np.where(inner, delta, 0.0) * math.radians(step)
    return np.sin(phi)
