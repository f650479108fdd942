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
    n_r = p.shape[0]
    # cumulative sums along range give every window sum in O(n)
    c = np.concatenate([np.zeros((1,) + p.shape[1:]), np.cumsum(p, axis=0)], axis=0)
    idx = np.arange(n_r)

    def window_sum(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo = np.clip(lo, 0, n_r)
        hi = np.clip(hi, 0, n_r)
        return c[hi] - c[lo], (hi - lo).astype(np.float64)

    lead_sum, lead_n = window_sum(idx - g - t, idx - g)
    lag_sum, lag_n = window_sum(idx + g + 1, idx + g + 1 + t)
    count = np.maximum(lead_n + lag_n, 1.0).reshape((-1,) + (1,) * (p.ndim - 1))
    mean_train = (lead_sum + lag_sum) / count
    noise = 10.0 ** (cfg.noise_floor_db / 10.0)
    alpha = 10.0 ** (cfg.cfar_threshold_db / 10.0)
    mask = (p > alpha * (mean_train + noise)) & (p > noise * 10.0 ** (cfg.min_snr_db / 10.0))
    if cfg.peak_grouping:
        mask &= p >= ndimage.maximum_filter(p, size=3, mode="constant", cval=0.0)
    return mask


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
