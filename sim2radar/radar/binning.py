"""Range-azimuth-elevation binning of returns (NumPy side) and the accumulated cube.

Bins: range bin ``i`` is centred at ``i * dR`` (FFT bins, ``round(range / dR)``); azimuth and
elevation bins tile the field of view uniformly (see :class:`~sim2radar.radar.RadarConfig`).
Amplitudes are summed coherently (complex); alongside, the power-weighted mean range, azimuth
and elevation of the contributions of each cell are kept so detections can be placed at the
interpolated peak position rather than the bin centre.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from sim2radar.radar.config import RadarConfig

__all__ = ["Accumulator", "bin_indices", "accumulate"]


@dataclasses.dataclass(frozen=True)
class Accumulator:
    """Flat per-cell sums (length ``n_range * n_az * n_el``, C order of the cube).

    Attributes
    ----------
    re, im : float64 — real and imaginary part of the coherent sum [sim. amplitude].
    power : float64 — sum of ``|a|^2`` of the contributions.
    range_w, azimuth_w, elevation_w : float64 — power-weighted sums of range [m],
        azimuth [rad] and elevation [rad].
    """

    re: np.ndarray
    im: np.ndarray
    power: np.ndarray
    range_w: np.ndarray
    azimuth_w: np.ndarray
    elevation_w: np.ndarray

    def cube(self, shape: tuple[int, int, int]) -> np.ndarray:
        """The complex64 cube of the given (n_range, n_az, n_el) shape."""
        return (self.re + 1j * self.im).astype(np.complex64).reshape(shape)


def bin_indices(
    range_m: np.ndarray, azimuth_rad: np.ndarray, elevation_rad: np.ndarray, radar: RadarConfig
) -> np.ndarray:
    """Flat cube index of each return, ``-1`` where it falls outside the cube.

    Parameters
    ----------
    range_m, azimuth_rad, elevation_rad : (N,) arrays [m], [rad], [rad]

    Returns
    -------
    (N,) int64
    """
    n_r, n_a, n_e = radar.n_range_bins, radar.n_azimuth_bins, radar.n_elevation_bins
    ir = np.floor(np.asarray(range_m) / radar.range_resolution_m + 0.5).astype(np.int64)
    ia = np.floor(
        (np.asarray(azimuth_rad) + 0.5 * radar.azimuth_fov_rad) / (radar.azimuth_fov_rad / n_a)
    ).astype(np.int64)
    ie = np.floor(
        (np.asarray(elevation_rad) + 0.5 * radar.elevation_fov_rad)
        / (radar.elevation_fov_rad / n_e)
    ).astype(np.int64)
    ok = (ir >= 0) & (ir < n_r) & (ia >= 0) & (ia < n_a) & (ie >= 0) & (ie < n_e)
    return np.where(ok, (ir * n_a + ia) * n_e + ie, -1)


def accumulate(
    index: np.ndarray,
    amplitude: np.ndarray,
    range_m: np.ndarray,
    azimuth_rad: np.ndarray,
    elevation_rad: np.ndarray,
    n_cells: int,
) -> Accumulator:
    """Coherently sum complex ``amplitude`` into cells ``index`` (``-1`` = dropped)."""
    ok = index >= 0
    idx = index[ok]
    a = np.asarray(amplitude)[ok]
    p = np.abs(a) ** 2

    def add(w: np.ndarray) -> np.ndarray:
        return np.bincount(idx, weights=w, minlength=n_cells).astype(np.float64)

    return Accumulator(
        re=add(a.real),
        im=add(a.imag),
        power=add(p),
        range_w=add(p * np.asarray(range_m)[ok]),
        azimuth_w=add(p * np.asarray(azimuth_rad)[ok]),
        elevation_w=add(p * np.asarray(elevation_rad)[ok]),
    )
