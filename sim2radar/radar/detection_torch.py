"""The ray tracer's frame detection in torch, on the device its sums live on (issue #31).

:func:`detect_frame` is the torch twin of :func:`sim2radar.radar.detection.detect_frame` in the
``integrated`` domain (TI's chain; module doc there): the channel signal of every Doppler slab
from the fine azimuth grid (:meth:`sim2radar.radar.binning.Accumulator.aperture`: an inverse FFT
per element row and range bin), receiver noise
(:func:`sim2radar.radar.binning.add_receiver_noise`'s model, drawn in two steps as there:
:func:`integrated_power`, :func:`row_noise`), the range-Doppler map, the dual-pass CFAR
(:func:`cfar_1d`, twin of :func:`sim2radar.radar.cfar.cfar_1d`), the azimuth peaks of each
detected cell and their refined directions, intensities and ranges
(:func:`sim2radar.radar.detection.peak_points`). Everything runs on the device of the
:class:`DeviceAccumulator` (the CUDA device where Mitsuba traces on ``cuda_ad_rgb``: the sums
never leave it); what comes back to the host is the point cloud (and, to pick the detected
cells, their count).

Same model, same arithmetic precision as the NumPy chain (complex64 channel signals, float64
maps and peak refinement); the FFTs and sums round differently (float32: ~1e-7 of the largest
channel signal), so points agree with NumPy's to float rounding, not to the bit. Receiver
noise is drawn from a ``torch.Generator`` (a different stream of the same distribution as
NumPy's; :func:`noise_generator`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from sim2radar.radar import cfar as np_cfar
from sim2radar.radar.binning import Accumulator, ArrayGeometry, array_geometry
from sim2radar.radar.config import RadarConfig
from sim2radar.radar.detection import (
    Detections,
    _offsets,
    cell_noise_power,
    doppler_bins,
)

__all__ = ["DeviceAccumulator", "cfar_1d", "detect_frame", "integrated_power",
           "noise_generator", "row_noise"]


@dataclasses.dataclass(frozen=True, eq=False)
class DeviceAccumulator:
    """:class:`~sim2radar.radar.binning.Accumulator` as torch tensors on one device.

    Attributes
    ----------
    grid : (n_z, n_range, M) complex64 tensor [sim. amplitude].
    power : (n_range * n_az * n_el,) float64 tensor [sim. |a|^2].
    range_w : (n_range * n_az * n_el,) float64 tensor [sim. |a|^2 m].
    """

    grid: Any
    power: Any
    range_w: Any

    @property
    def device(self):
        return self.grid.device

    def to_host(self) -> Accumulator:
        """The NumPy :class:`Accumulator` (one read-back)."""
        return Accumulator(grid=self.grid.cpu().numpy(), power=self.power.cpu().numpy(),
                           range_w=self.range_w.cpu().numpy())


def noise_generator(seed: int, stream: int, device):
    """A ``torch.Generator`` on ``device`` for the words ``(seed, stream)`` (NumPy's
    ``SeedSequence`` mixes them into one 63-bit seed, as ``default_rng([seed, stream])`` does)."""
    import torch

    word = int(np.random.SeedSequence([int(seed), int(stream)]).generate_state(1, np.uint64)[0])
    return torch.Generator(device=device).manual_seed(word & ((1 << 63) - 1))


def _aperture(grid, geom: ArrayGeometry, masks):
    """(S, n_range, n_z, n_x) complex64 — the channel signal of each Doppler slab (``masks``
    (S, M) bool over the fine azimuth points; :meth:`Accumulator.aperture`)."""
    import torch

    dev = grid.device
    g = grid[None] * masks[:, None, None, :].to(grid.dtype)                 # (S, n_z, n_r, M)
    if geom.integer_x:
        n, post = geom._fft_terms
        s = torch.fft.ifft(g, dim=-1)[..., torch.as_tensor(n, device=dev)]
        s = s * torch.as_tensor(post, device=dev, dtype=torch.complex64)
    else:
        s = torch.einsum("szrg,gx->szrx", g, torch.as_tensor(geom.fine_phases, device=dev,
                                                             dtype=torch.complex64))
    return s.transpose(1, 2)


def integrated_power(signal_power, n_channels: int, variance: float, gen):
    """Torch twin of :func:`sim2radar.radar.binning.integrated_power`: ``(power, (parallel,
    rest))`` of rows whose signal power is ``signal_power`` (float64 tensor), drawn from
    ``gen`` on its device."""
    import torch

    dev, shape = signal_power.device, tuple(signal_power.shape)
    a = signal_power.to(torch.float64).sqrt()
    z = torch.randn((2, *shape), generator=gen, device=dev, dtype=torch.float64)
    z = z * math.sqrt(variance / 2.0)
    if n_channels > 1:
        k = torch.full(shape, float(n_channels - 1), dtype=torch.float64, device=dev)
        rest = torch._standard_gamma(k, generator=gen) * variance
    else:
        rest = torch.zeros(shape, dtype=torch.float64, device=dev)
    power = (a + z[0]) ** 2 + z[1] ** 2 + rest
    return power, (torch.complex(z[0], z[1]), rest)


def row_noise(signal, parallel, rest, gen):
    """Torch twin of :func:`sim2radar.radar.binning.row_noise`: (K, C) complex128 noise of K
    rows of ``signal`` consistent with their drawn ``parallel`` component and ``rest`` power."""
    import torch

    v = signal.to(torch.complex128)
    k, n_ch = v.shape
    a = v.abs().pow(2).sum(dim=1).sqrt()
    e = torch.zeros_like(v)
    e[:, 0] = 1.0
    has = a > 0
    e[has] = v[has] / a[has, None]
    g = torch.randn((2, k, n_ch), generator=gen, device=v.device, dtype=torch.float64)
    g = torch.complex(g[0], g[1])
    g = g - e * (e.conj() * g).sum(dim=1, keepdim=True)
    norm = g.abs().pow(2).sum(dim=1, keepdim=True).sqrt()
    u = torch.where(norm > 0, g / torch.where(norm > 0, norm, 1.0), torch.zeros_like(g))
    return parallel[:, None] * e + rest.sqrt()[:, None] * u


def cfar_1d(power, *, axis: int, kind: str, guard: int, train: int, alpha: float,
            edges: str = "wrap", discard: tuple[int, int] = (0, 0), rank: float = 0.75):
    """One CFAR pass along ``axis`` of a float tensor: torch twin of
    :func:`sim2radar.radar.cfar.cfar_1d` (same windows, edges and kinds); returns the bool
    detection mask."""
    import torch

    p = torch.movedim(power, axis, -1)
    n_len = p.shape[-1]
    g, n, span, lo, hi = np_cfar.cfar_window(n_len, kind=kind, guard=guard, train=train,
                                             edges=edges, discard=discard)
    v = p[..., lo:n_len - hi]
    length = v.shape[-1]
    if edges == "wrap":
        padded = torch.cat([v[..., length - span:], v, v[..., :span]], dim=-1)
    else:
        padded = torch.cat([v[..., :span], v, v[..., length - span:]], dim=-1)
    win = padded.unfold(-1, n, 1)                                           # (..., L+2s-n+1, n)
    j = torch.arange(length, device=p.device)
    left = win[..., j + span - g - n, :]
    right = win[..., j + span + g + 1, :]
    if kind == "ca":
        z = 0.5 * (left.mean(dim=-1) + right.mean(dim=-1))
    elif kind == "caso":
        z = torch.minimum(left.mean(dim=-1), right.mean(dim=-1))
    else:
        k = max(1, min(2 * n, math.ceil(rank * 2 * n - 1e-9)))
        z = torch.cat([left, right], dim=-1).kthvalue(k, dim=-1).values
    detected = torch.zeros(p.shape, dtype=torch.bool, device=p.device)
    detected[..., lo:n_len - hi] = v > alpha * z
    return torch.movedim(detected, -1, axis)


def _azimuth_steer(geom: ArrayGeometry, device):
    """(n_x, n_a) complex64 — the main row's weights times ``e^{-j pi x u_a}`` on the azimuth
    bins (:func:`sim2radar.radar.binning.azimuth_map` as one matrix)."""
    import torch

    steer = geom.main_weight[:, None] * np.exp(-1j * math.pi * np.outer(geom.x_half_wl,
                                                                       geom.u_az))
    return torch.as_tensor(steer, device=device, dtype=torch.complex64)


def _azimuth_response(main, geom: ArrayGeometry, u_az, offsets):
    """(K, P) complex128 — :func:`sim2radar.radar.binning.azimuth_response` of the weighted
    main-row signals ``main`` (K, n_x) complex128 at ``u_az`` (K,) + ``offsets`` (P,)."""
    import torch

    x = torch.as_tensor(geom.x_half_wl, device=main.device)
    m = main * torch.exp(-1j * math.pi * u_az[:, None] * x[None])
    return m @ torch.exp(-1j * math.pi * x[:, None] * offsets[None, :])


def _refine(centre, values, step: float):
    """Refined argmax of ``|values|`` (K, P) sampled at ``centre + (p - P // 2) step``
    (:func:`sim2radar.radar.detection._refine_peak`)."""
    import torch

    logp = torch.log(torch.clamp(values.abs() ** 2, min=1e-300))
    n = values.shape[1]
    p = logp.argmax(dim=1)
    pc = torch.clamp(p, 1, max(n - 2, 1))
    if n >= 3:
        k = torch.arange(len(values), device=values.device)
        y_m, y_0, y_p = logp[k, pc - 1], logp[k, pc], logp[k, pc + 1]
        den = y_m - 2.0 * y_0 + y_p
        ok = den < 0
        off = torch.where(ok, 0.5 * (y_m - y_p) / torch.where(ok, den, -1.0), 0.0)
        off = torch.where(p == pc, torch.clamp(off, -1.0, 1.0), 0.0)
    else:
        off = torch.zeros(len(values), dtype=logp.dtype, device=values.device)
    return centre + (p - n // 2 + off) * step


def _peak_points(rows, ir, ia, acc: DeviceAccumulator, radar: RadarConfig):
    """(K, 4) float32 tensor of K azimuth peaks: torch twin of
    :func:`sim2radar.radar.detection.peak_points` (float64 / complex128 as there)."""
    import torch

    dev = rows.device
    geom = array_geometry(radar)
    rows = rows.to(torch.complex128)
    rng = torch.as_tensor(radar.range_bins_m.astype(np.float64), device=dev)[ir]
    u_az = torch.as_tensor(geom.u_az, device=dev)
    main = torch.as_tensor(geom.main_weight, device=dev)[None] * rows[:, geom.main_row, :]
    offsets, step = _offsets(radar.azimuth_bin_u, 1.0)
    u0 = u_az[ia]
    ua = _refine(u0, _azimuth_response(main, geom, u0, torch.as_tensor(offsets, device=dev)),
                 step)
    ua = torch.clamp(ua, max(-1.0, geom.u_az[0] - 0.5 * radar.azimuth_bin_u),
                     min(1.0, geom.u_az[-1] + 0.5 * radar.azimuth_bin_u))
    zero = torch.zeros(1, dtype=torch.float64, device=dev)
    peak_power = _azimuth_response(main, geom, ua, zero)[:, 0].abs() ** 2
    # elevation: the 2D beam at that azimuth over the elevation bins' extent (beam_response)
    el_mid = 0.5 * (geom.u_el[0] + geom.u_el[-1])
    half_span = 0.5 * (geom.u_el[-1] - geom.u_el[0]) / radar.elevation_bin_u + 0.5
    el_off, el_step = _offsets(radar.elevation_bin_u, half_span)
    el_grid = np.clip(el_mid + el_off, -1.0, 1.0)
    w = torch.as_tensor(geom.weight, device=dev)[None] * rows                  # (K, n_z, n_x)
    ex = torch.exp(-1j * math.pi * ua[:, None]
                   * torch.as_tensor(geom.x_half_wl, device=dev)[None, :])
    per_row = torch.einsum("kzx,kx->kz", w, ex)
    ez = torch.as_tensor(np.exp(-1j * math.pi * np.outer(geom.z_half_wl, el_grid)), device=dev)
    ue = _refine(torch.full_like(ua, el_mid), per_row @ ez, el_step)
    ue = torch.clamp(ue, float(el_grid[0]), float(el_grid[-1]))
    # range: power-weighted over the detected beam and its two neighbours, all elevations
    n_a, n_e = radar.n_azimuth_bins, radar.n_elevation_bins
    beams = torch.clamp(ia[:, None] + torch.arange(-1, 2, device=dev)[None, :], 0, n_a - 1)
    cells = ((ir[:, None, None] * n_a + beams[:, :, None]) * n_e
             + torch.arange(n_e, device=dev)[None, None, :]).reshape(len(ir), -1)
    wsum = acc.power[cells].sum(dim=1)
    ok = wsum > 0
    rng = torch.where(ok, acc.range_w[cells].sum(dim=1) / torch.where(ok, wsum, 1.0), rng)
    intensity_db = 10.0 * torch.log10(4.0 * math.pi * torch.clamp(peak_power, min=1e-30))
    x = torch.sqrt(torch.clamp(1.0 - ua**2 - ue**2, min=0.0))
    return torch.stack([rng * x, rng * ua, rng * ue, intensity_db], dim=1).to(torch.float32)


def detect_frame(acc: DeviceAccumulator, radar: RadarConfig, *,
                 velocity_mps: np.ndarray | None = None, generator=None) -> Detections:
    """Detect one traced frame on ``acc``'s device (``integrated`` domain): torch twin of
    :func:`sim2radar.radar.detection.detect_frame`.

    Parameters
    ----------
    acc : DeviceAccumulator — the frame's sums on the device.
    radar : RadarConfig — ``detection.domain`` must be ``integrated``.
    velocity_mps : (3,), optional — rig velocity in the radar frame [m/s] (Doppler slabs).
    generator : torch.Generator on ``acc.device``, optional — receiver noise (None: noise-free,
        the CFAR on the expected noise).

    Returns
    -------
    Detections — NumPy points (N, 4) float32 and Doppler (N,) float32, strongest first.
    """
    import torch

    cfg = radar.detection
    if cfg.domain != "integrated":
        raise ValueError("the torch detector runs the integrated domain; use "
                         "sim2radar.radar.detection.detect_frame for 'range-azimuth'")
    dev = acc.device
    geom = array_geometry(radar)
    n0 = cell_noise_power(radar)
    n_r, n_d = radar.n_range_bins, radar.n_chirps
    bins = doppler_bins(radar, velocity_mps)
    slabs = np.unique(bins)
    masks = torch.as_tensor(bins[None, :] == slabs[:, None], device=dev)
    ap = _aperture(acc.grid, geom, masks)                                   # (S, n_r, n_z, n_x)
    present = torch.as_tensor(geom.present, device=dev)
    n_pos = int(geom.present.sum())
    chan_noise = geom.n_elements * n0
    mean_noise = chan_noise * n_pos
    power = ap.real**2 + ap.imag**2                                         # (S, n_r, n_z, n_x)
    # over the array's channels (the positions holding a virtual element), as NumPy's
    profile = (power * present.to(power.dtype)).sum(dim=(-2, -1), dtype=torch.float64)
    if generator is not None:
        shape = torch.full((n_r, n_d), float(n_pos), dtype=torch.float64, device=dev)
        rd = torch._standard_gamma(shape, generator=generator) * chan_noise
        profile, (parallel, rest) = integrated_power(profile, n_pos, chan_noise, generator)
    else:
        rd = torch.full((n_r, n_d), mean_noise, dtype=torch.float64, device=dev)
        profile = profile + mean_noise
    cols = torch.as_tensor(np.mod(slabs, n_d), device=dev)
    rd[:, cols] = profile.T
    det = cfar_1d(rd, axis=0, kind=cfg.cfar_kind, guard=cfg.cfar_guard_cells,
                  train=cfg.cfar_training_cells, alpha=10.0 ** (cfg.cfar_threshold_db / 10.0),
                  edges="ti", discard=cfg.cfar_discard_range_bins)
    span = 2 * (cfg.doppler_cfar_guard_cells + cfg.doppler_cfar_training_cells) + 1
    if n_d >= span:
        det &= cfar_1d(rd, axis=1, kind=cfg.cfar_kind, guard=cfg.doppler_cfar_guard_cells,
                       train=cfg.doppler_cfar_training_cells,
                       alpha=10.0 ** (cfg.doppler_cfar_threshold_db / 10.0), edges="wrap")
    slab_of_col = torch.full((n_d,), -1, dtype=torch.int64, device=dev)
    slab_of_col[cols] = torch.arange(len(slabs), device=dev)
    ri, ci = torch.nonzero(det, as_tuple=True)
    si = slab_of_col[ci]
    has = si >= 0                          # a noise-only cell cannot pass the minimum SNR
    ri, ci, si = ri[has], ci[has], si[has]
    empty = Detections(np.zeros((0, 4), np.float32), np.zeros(0, np.float32))
    if len(ri) == 0:
        return empty
    rows = ap[si, ri]                                                       # (K, n_z, n_x)
    if generator is not None:
        rows = rows.clone()
        sig = rows[:, present]                                              # (K, n_pos)
        noise = row_noise(sig, parallel[si, ri], rest[si, ri], generator)
        rows[:, present] = (sig.to(torch.complex128) + noise).to(rows.dtype)
    amap = rows[:, geom.main_row, :] @ _azimuth_steer(geom, dev)            # (K, n_a)
    p = amap.to(torch.complex128).abs() ** 2
    cand = p > n0 * geom.main_noise_factor * 10.0 ** (cfg.min_snr_db / 10.0)
    if cfg.sidelobe_level_db is not None:
        cand &= p >= p.amax(dim=1, keepdim=True) * 10.0 ** (-cfg.sidelobe_level_db / 10.0)
    cand[:, 1:] &= p[:, 1:] >= p[:, :-1]                    # local maxima along azimuth
    cand[:, :-1] &= p[:, :-1] >= p[:, 1:]
    k, ia = torch.nonzero(cand, as_tuple=True)
    if len(k) == 0:
        return empty
    points = _peak_points(rows[k], ri[k], ia, acc, radar)
    d_of = torch.remainder(ci[k] + n_d // 2, n_d) - n_d // 2
    doppler = (d_of.to(torch.float64) * radar.range_rate_resolution_mps).to(torch.float32)
    order = torch.sort(-points[:, 3], stable=True).indices
    points, doppler = points[order], doppler[order]
    if cfg.max_points is not None:
        points, doppler = points[: cfg.max_points], doppler[: cfg.max_points]
    return Detections(points.cpu().numpy(), doppler.cpu().numpy())
