"""Peak detection on the range-azimuth-elevation cube: CA-CFAR along range + local maxima.

Cell-averaging CFAR (Richards, *Fundamentals of Radar Signal Processing*, 2nd ed., §6.5):
for each cell, the interference estimate is the mean power of ``T`` training cells on each
side along range, skipping ``G`` guard cells; the cell is detected if::

    P > alpha * (mean_training + N0),     alpha = 10^(threshold_db / 10)
    P > N0 * 10^(min_snr_db / 10)         (N0 = 10^(noise_floor_db / 10), per-cell noise)

and, with ``peak_grouping``, ``P`` is the maximum of its 3x3x3 neighbourhood (one point per
peak, like the peak grouping of TI's mmWave SDK). Points are placed at the power-weighted mean
range/azimuth/elevation of the contributions that fell into the cell (an interpolated peak
position within the bin), or at the bin centre if that is unavailable.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from sim2radar.radar.binning import Accumulator
from sim2radar.radar.config import DetectionConfig, RadarConfig

__all__ = ["ca_cfar_mask", "detect_points", "spherical_to_cartesian"]


def ca_cfar_mask(power: np.ndarray, cfg: DetectionConfig) -> np.ndarray:
    """Boolean detection mask of a (n_range, n_az, n_el) power cube (CA-CFAR along axis 0)."""
    p = np.asarray(power, dtype=np.float64)
    g, t = cfg.cfar_guard_cells, cfg.cfar_training_cells
    # training cells = (full window of 2(g+t)+1 cells) - (guard window of 2g+1 cells),
    # both as O(n) running sums along range (zero-padded beyond the ends)
    n_full, n_guard = 2 * (g + t) + 1, 2 * g + 1

    def window_sum(a: np.ndarray, size: int, axis: int = 0) -> np.ndarray:
        return size * ndimage.uniform_filter1d(a, size, axis=axis, mode="constant", cval=0.0)

    train_sum = window_sum(p, n_full) - window_sum(p, n_guard)
    ones = np.ones(p.shape[0])
    count = window_sum(ones, n_full) - window_sum(ones, n_guard)  # fewer near the ends
    shape = (-1,) + (1,) * (p.ndim - 1)
    mean_train = train_sum / np.maximum(count, 1.0).reshape(shape)
    noise = 10.0 ** (cfg.noise_floor_db / 10.0)
    alpha = 10.0 ** (cfg.cfar_threshold_db / 10.0)
    mask = (p > alpha * (mean_train + noise)) & (p > noise * 10.0 ** (cfg.min_snr_db / 10.0))
    if cfg.peak_grouping:
        mask &= _is_local_max(p, mask)
    return mask


def _is_local_max(p: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """True where a candidate cell is >= all its 3^ndim - 1 neighbours (zero outside).

    Only the (few) candidate cells are tested, which is much cheaper than a full
    maximum filter over the cube.
    """
    idx = np.nonzero(candidates)
    out = np.zeros_like(candidates)
    if len(idx[0]) == 0:
        return out
    padded = np.pad(p, 1, mode="constant", constant_values=0.0)
    centre = p[idx]
    keep = np.ones(len(centre), dtype=bool)
    for offset in np.ndindex(*(3,) * p.ndim):
        if all(o == 1 for o in offset):
            continue
        neighbour = padded[tuple(i + o for i, o in zip(idx, offset, strict=True))]
        keep &= centre >= neighbour
    out[tuple(i[keep] for i in idx)] = True
    return out


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


def detect_points(cube: np.ndarray, acc: Accumulator | None, radar: RadarConfig) -> np.ndarray:
    """Detect peaks in a complex cube and return the point cloud.

    Parameters
    ----------
    cube : (n_range, n_az, n_el) complex — coherent returns (noise included if any).
    acc : Accumulator or None — for interpolated positions (power-weighted centroids).
    radar : RadarConfig

    Returns
    -------
    points : (N, 4) float32 — x, y, z [m] (radar frame), intensity [dB]
        (``10 log10(4 pi |a|^2)``, see :mod:`sim2radar.radar.returns`), strongest first.
    """
    power = np.abs(cube.astype(np.complex128)) ** 2
    mask = ca_cfar_mask(power, radar.detection)
    ir, ia, ie = np.nonzero(mask)
    flat = np.ravel_multi_index((ir, ia, ie), power.shape)
    rng = radar.range_bins_m.astype(np.float64)[ir]
    az = radar.azimuth_bins_rad.astype(np.float64)[ia]
    el = radar.elevation_bins_rad.astype(np.float64)[ie]
    if acc is not None and len(flat):
        w = acc.power[flat]
        ok = w > 0
        safe = np.where(ok, w, 1.0)
        rng = np.where(ok, acc.range_w[flat] / safe, rng)
        az = np.where(ok, acc.azimuth_w[flat] / safe, az)
        el = np.where(ok, acc.elevation_w[flat] / safe, el)
    intensity_db = 10.0 * np.log10(4.0 * np.pi * np.maximum(power[mask], 1e-30))
    xyz = spherical_to_cartesian(rng, az, el)
    points = np.concatenate([xyz, intensity_db[:, None]], axis=1).astype(np.float32)
    order = np.argsort(-points[:, 3], kind="stable")
    points = points[order]
    if radar.detection.max_points is not None:
        points = points[: radar.detection.max_points]
    return points
