"""Peak detection of the ray tracer: CA-CFAR along range, local maxima, angles from the array
response (the detectors themselves are :mod:`sim2radar.radar.cfar`, shared with the reference
radar).

Following TI's cascade chain (``DOA_beamformingFFT_2D``, see :mod:`sim2radar.radar.binning`),
peaks are found in the range-azimuth map ``A`` of the complete azimuth row and each peak's
elevation is read from the 2D beam ``B`` at its azimuth.

Cell-averaging CFAR (Richards, *Fundamentals of Radar Signal Processing*, 2nd ed., §6.5):
for each cell of the power map, the interference estimate is the mean power of ``T``
training cells on each side along range, skipping ``G`` guard cells; the cell is detected if::

    P > alpha * (mean_training + N),     alpha = 10^(threshold_db / 10)
    P > N * 10^(min_snr_db / 10)

with ``N`` the map's receiver noise per cell: ``N0`` (:func:`cell_noise_power`: the link
budget's :func:`~sim2radar.radar.link_budget.noise_power_per_cell`, or
``detection.noise_floor_db`` when set) times the map's noise factor (``N / n`` for ``n`` of the
``N`` channels used), and, with ``peak_grouping``, ``P`` the maximum of its neighbourhood (3
cells per axis; one point per peak, like the peak grouping of TI's mmWave SDK). Peaks more than
``sidelobe_level_db`` below the strongest cell of their range bin are dropped as sidelobes of
the array response (TI's ``sidelobeLevel_dB_azim`` rule, see
:class:`~sim2radar.radar.config.DetectionConfig`).

A point's direction is estimated as the array would: ``A`` of its range bin is evaluated on
9 quarter-bin steps around the detected beam and its maximum refined by a 3-point parabola
(on ``log |A|^2``, exact for a Gaussian main lobe); the intensity is read at the refined peak
(a target between two beams is not read low). The elevation is the maximum of ``B`` at that
azimuth over the elevation field of view (quarter-bin steps, parabola). Two scatterers
closer than a beamwidth therefore give one point between them; off boresight the beams, and
the angle uncertainty, widen as ``1 / cos``. One point per (range, azimuth) peak: returns at
the same range and azimuth but different elevations (floor and ceiling) merge, as in TI's
chain when one elevation peak dominates. The range is the power-weighted mean range of the
contributions in the detected range bin within one beam of the peak (within half a range bin
of the bin centre).

Given only a beam cube (no channel signal), detection runs on the 3D power cube and points sit
at the cell centres.
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.radar import cfar
from sim2radar.radar.binning import (
    Accumulator,
    array_geometry,
    azimuth_map,
    azimuth_response,
    beam_response,
)
from sim2radar.radar.config import DetectionConfig, RadarConfig

__all__ = [
    "ca_cfar_mask",
    "cell_noise_power",
    "detect_points",
    "direction_to_cartesian",
    "spherical_to_cartesian",
]

#: Steps per bin of the local grids the peaks are refined on (quarter-bin steps).
REFINE_STEPS_PER_BIN = 4


def cell_noise_power(radar: RadarConfig) -> float:
    """Receiver noise ``N0`` per beam cell [sim. ``|a|^2``]: ``detection.noise_floor_db`` if set,
    else derived from the hardware link budget (``k T F f_s`` over echo scale and processing
    gain, :func:`sim2radar.radar.link_budget.noise_power_per_cell`)."""
    if radar.detection.noise_floor_db is not None:
        return 10.0 ** (radar.detection.noise_floor_db / 10.0)
    from sim2radar.radar.link_budget import noise_power_per_cell

    return float(noise_power_per_cell(radar))


def ca_cfar_mask(
    power: np.ndarray, cfg: DetectionConfig, noise_power: float | None = None
) -> np.ndarray:
    """Boolean detection mask of a (n_range, ...) power map or cube: the ray tracer's detector
    (:func:`sim2radar.radar.cfar.ca_cfar_mask` with ``cfg``'s settings).

    Parameters
    ----------
    power : (n_range, ...) float — cell power [sim. |a|^2].
    cfg : DetectionConfig
    noise_power : float, optional — ``N0`` per cell [sim. |a|^2]; default
        ``10^(cfg.noise_floor_db / 10)`` (required when that is unset).
    """
    if noise_power is None:
        if cfg.noise_floor_db is None:
            raise ValueError("noise_power is required when detection.noise_floor_db is derived "
                             "(pass cell_noise_power(radar))")
        noise_power = 10.0 ** (cfg.noise_floor_db / 10.0)
    return cfar.ca_cfar_mask(
        power, guard=cfg.cfar_guard_cells, train=cfg.cfar_training_cells,
        threshold_db=cfg.cfar_threshold_db, noise_power=noise_power, min_snr_db=cfg.min_snr_db,
        sidelobe_level_db=cfg.sidelobe_level_db, peak_grouping=cfg.peak_grouping)


def spherical_to_cartesian(
    range_m: np.ndarray, azimuth_rad: np.ndarray, elevation_rad: np.ndarray
) -> np.ndarray:
    """(N, 3) x, y, z [m] in the radar frame (x forward, y left, z up)."""
    ce = np.cos(elevation_rad)
    return np.stack(
        [
            range_m * ce * np.cos(azimuth_rad),
            range_m * ce * np.sin(azimuth_rad),
            range_m * np.sin(elevation_rad),
        ],
        axis=1,
    )


def direction_to_cartesian(range_m: np.ndarray, u_az: np.ndarray, u_el: np.ndarray) -> np.ndarray:
    """(N, 3) x, y, z [m] from range [m] and direction cosines ``u_a = y / r``, ``u_e = z / r``
    (``x = r sqrt(1 - u_a^2 - u_e^2)``, clipped at 0)."""
    r = np.asarray(range_m, dtype=np.float64)
    ua, ue = np.asarray(u_az, dtype=np.float64), np.asarray(u_el, dtype=np.float64)
    x = np.sqrt(np.maximum(1.0 - ua**2 - ue**2, 0.0))
    return np.stack([r * x, r * ua, r * ue], axis=1)


def _refine_peak(centre: np.ndarray, values: np.ndarray, step: float) -> np.ndarray:
    """Refined argmax of |values| (K, P) sampled at ``centre[k] + (p - P // 2) step``."""
    logp = np.log(np.maximum(np.abs(values) ** 2, 1e-300))
    k = np.arange(len(values))
    n = values.shape[1]
    p = logp.argmax(axis=1)
    pc = np.clip(p, 1, max(n - 2, 1))
    if n >= 3:
        off, _ = cfar.parabolic_peak(logp[k, pc - 1], logp[k, pc], logp[k, pc + 1],
                                     max_offset=1.0)
        off = np.where(p == pc, off, 0.0)
    else:
        off = np.zeros(len(values))
    return centre + (p - n // 2 + off) * step


def _offsets(width: float, half_bins: float) -> tuple[np.ndarray, float]:
    """Quarter-bin offsets spanning +-``half_bins`` bins of ``width`` [-], and the step."""
    step = width / REFINE_STEPS_PER_BIN
    n = int(round(half_bins * REFINE_STEPS_PER_BIN))
    return np.arange(-n, n + 1) * step, step


def detect_points(
    cube: np.ndarray,
    acc: Accumulator | None,
    radar: RadarConfig,
    aperture: np.ndarray | None = None,
) -> np.ndarray:
    """Detect peaks and return the point cloud.

    Parameters
    ----------
    cube : (n_range, n_az, n_el) complex — 2D beams on the bin centres (used only when no
        channel signal is available).
    acc : Accumulator or None — per-cell range sums (sub-bin ranges) and, if ``aperture`` is
        not given, the (noise-free) channel signal.
    radar : RadarConfig
    aperture : (n_range, n_z, n_x) complex, optional — the channel signal, noise included
        (:meth:`Accumulator.aperture`, :func:`sim2radar.radar.binning.add_receiver_noise`).

    Returns
    -------
    points : (N, 4) float32 — x, y, z [m] (radar frame), intensity [dB]
        (``10 log10(4 pi |a|^2)``, see :mod:`sim2radar.radar.returns`), strongest first.
    """
    geom = array_geometry(radar)
    n0 = cell_noise_power(radar)
    if aperture is None and acc is not None:
        aperture = acc.aperture(geom)
    if aperture is None:  # beam cube only: 3D CFAR, cell centres
        power = np.abs(cube.astype(np.complex128)) ** 2
        mask = ca_cfar_mask(power, radar.detection, n0 * geom.noise_factor)
        ir, ia, ie = np.nonzero(mask)
        rng = radar.range_bins_m.astype(np.float64)[ir]
        ua, ue = radar.azimuth_bins_u[ia], radar.elevation_bins_u[ie]
        peak_power = power[ir, ia, ie]
    else:
        amap = azimuth_map(aperture, geom)
        power = np.abs(amap.astype(np.complex128)) ** 2
        mask = ca_cfar_mask(power, radar.detection, n0 * geom.main_noise_factor)
        ir, ia = np.nonzero(mask)
        rng = radar.range_bins_m.astype(np.float64)[ir]
        rows = aperture[ir]
        offsets, step = _offsets(radar.azimuth_bin_u, 1.0)
        ua = _refine_peak(geom.u_az[ia], azimuth_response(rows, geom, geom.u_az[ia], offsets),
                          step)
        ua = np.clip(ua, max(-1.0, geom.u_az[0] - 0.5 * radar.azimuth_bin_u),
                     min(1.0, geom.u_az[-1] + 0.5 * radar.azimuth_bin_u))
        peak_power = np.abs(azimuth_response(rows, geom, ua)[:, 0]) ** 2
        # elevation: the 2D beam at that azimuth over the elevation bins' extent
        el_mid = 0.5 * (geom.u_el[0] + geom.u_el[-1])
        half_span = 0.5 * (geom.u_el[-1] - geom.u_el[0]) / radar.elevation_bin_u + 0.5
        el_off, el_step = _offsets(radar.elevation_bin_u, half_span)
        el_grid = np.clip(el_mid + el_off, -1.0, 1.0)
        if len(ir):
            ue = _refine_peak(np.full(len(ir), el_mid),
                              beam_response(rows, geom, ua, el_grid), el_step)
            ue = np.clip(ue, el_grid[0], el_grid[-1])
        else:
            ue = np.zeros(0)
        if acc is not None and len(ir):
            # the detected beam and its two neighbours (a peak between beams), all elevations
            n_a, n_e = radar.n_azimuth_bins, radar.n_elevation_bins
            beams = np.clip(ia[:, None] + np.arange(-1, 2)[None, :], 0, n_a - 1)  # (K, 3)
            cells = ((ir[:, None, None] * n_a + beams[:, :, None]) * n_e
                     + np.arange(n_e)[None, None, :]).reshape(len(ir), -1)
            w = acc.power[cells].sum(axis=1)
            ok = w > 0
            rng = np.where(ok, acc.range_w[cells].sum(axis=1) / np.where(ok, w, 1.0), rng)
    intensity_db = 10.0 * np.log10(4.0 * math.pi * np.maximum(peak_power, 1e-30))
    xyz = direction_to_cartesian(rng, ua, ue)
    points = np.concatenate([xyz, intensity_db[:, None]], axis=1).astype(np.float32)
    order = np.argsort(-points[:, 3], kind="stable")
    points = points[order]
    if radar.detection.max_points is not None:
        points = points[: radar.detection.max_points]
    return points
