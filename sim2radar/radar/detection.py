"""Peak detection of the ray tracer: where its CFAR runs, the azimuth peaks, the angles from
the array response (the detectors themselves are :mod:`sim2radar.radar.cfar`, shared with the
reference radar).

Following TI's cascade chain (``DOA_beamformingFFT_2D``, see :mod:`sim2radar.radar.binning`),
azimuth peaks are found in the range-azimuth map ``A`` of the complete azimuth row and each
peak's elevation is read from the 2D beam ``B`` at its azimuth. Which range bins and cells
are tested is :attr:`DetectionConfig.domain`:

* ``integrated`` (the default; TI's chain for a rig at rest, :func:`integrated_detection_mask`):
  a CFAR along range on the range profile integrated over the virtual channels,
  ``P[i] = sum_(x, z) |s(x, z)[i]|^2`` over the positions holding a virtual element (TI's
  detection matrix, ``CFAR_CASO/datapath.m``, with
  the one Doppler bin a static scene fills), TI's smallest-of cell averaging by default
  (:func:`sim2radar.radar.cfar.cfar_1d`, ``edges="ti"``); then in each detected range bin the
  azimuth peaks (local maxima along azimuth) above ``min_snr_db`` over the map's noise and
  within ``sidelobe_level_db`` of the bin's strongest.
* ``range-azimuth`` (:func:`ca_cfar_mask`): cell-averaging CFAR along range in every azimuth
  beam (Richards, *Fundamentals of Radar Signal Processing*, 2nd ed., §6.5)::

      P > alpha * (mean_training + N),     alpha = 10^(threshold_db / 10)
      P > N * 10^(min_snr_db / 10)

  with, under ``peak_grouping``, ``P`` the maximum of its neighbourhood (3 cells per axis),
  and the same sidelobe rule per range bin.

Why the default changed (docs/radar_model.md, "The multipath haze"): second-bounce diffuse
returns spread a weak field of multipath over every azimuth behind the walls and out to
``R_max``. A per-beam CFAR normalises to whatever the beam holds at that range, so where only
that field is (behind a wall, near ``R_max``) it detects its speckle at the CFAR's
false-alarm rate, beam after beam: a haze of points with no surface behind it. The device
integrates the channels first, so the field is compared with everything its range bin holds
and only range bins with a surface stand out. Measured on the same ground-truth frames, the
reference radar's own propagation paths give 64 % of points more than 1 m behind the first
surface through the per-beam CFAR and 21 % through TI's chain.

``N`` is the map's receiver noise per cell: ``N0`` (:func:`cell_noise_power`: the link
budget's :func:`~sim2radar.radar.link_budget.noise_power_per_cell`, or
``detection.noise_floor_db`` when set) times the map's noise factor (``N / n`` for ``n`` of
the ``N`` channels used).

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

Given only a beam cube (no channel signal), detection runs on the 3D power cube with the
range-azimuth CFAR and points sit at the cell centres.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.radar import cfar
from sim2radar.radar.binning import (
    Accumulator,
    RowNoise,
    add_receiver_noise,
    array_geometry,
    azimuth_map,
    azimuth_response,
    beam_response,
    integrated_power,
    row_noise,
)
from sim2radar.radar.config import DetectionConfig, RadarConfig

__all__ = [
    "Detections",
    "ca_cfar_mask",
    "detect_frame",
    "doppler_bins",
    "peak_points",
    "cell_noise_power",
    "channel_profile",
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
    *,
    noise_added: bool = False,
) -> np.ndarray:
    """Detect peaks of a rig at rest and return the point cloud
    (:func:`detect_frame` is the frame's detection, moving rig and receiver noise included).

    Parameters
    ----------
    cube : (n_range, n_az, n_el) complex — 2D beams on the bin centres (used only when no
        channel signal is available).
    acc : Accumulator or None — per-cell range sums (sub-bin ranges) and, if ``aperture`` is
        not given, the (noise-free) channel signal.
    radar : RadarConfig
    aperture : (n_range, n_z, n_x) complex, optional — the channel signal, noise included
        (:meth:`Accumulator.aperture`, :func:`sim2radar.radar.binning.add_receiver_noise`).
    noise_added : bool — whether ``aperture`` carries receiver noise; without it the
        integrated detector's CFAR adds the expected noise to the map it tests.

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
        intensity_db = 10.0 * np.log10(4.0 * math.pi * np.maximum(peak_power, 1e-30))
        xyz = direction_to_cartesian(rng, ua, ue)
        points = np.concatenate([xyz, intensity_db[:, None]], axis=1).astype(np.float32)
        return _strongest_first(points, np.zeros(len(points), np.float32), radar)[0]
    if radar.detection.domain == "integrated":
        return _detect_slabs(np.zeros(1, np.int64), np.asarray(aperture)[None], acc, radar,
                             noise="none" if noise_added else "expected").points
    amap = azimuth_map(aperture, geom)
    power = np.abs(amap.astype(np.complex128)) ** 2
    mask = ca_cfar_mask(power, radar.detection, n0 * geom.main_noise_factor)
    ir, ia = np.nonzero(mask)
    points = peak_points(aperture[ir], ir, ia, acc, radar)
    return _strongest_first(points, np.zeros(len(points), np.float32), radar)[0]


@dataclasses.dataclass(frozen=True)
class Detections:
    """The ray tracer's point cloud of one frame.

    Attributes
    ----------
    points : (N, 4) float32 — x, y, z [m] (radar frame), intensity [dB], strongest first.
    doppler_mps : (N,) float32 — range rate of each point's range-Doppler cell [m/s]
        (positive = receding; 0 for a rig at rest or the range-azimuth domain).
    """

    points: np.ndarray
    doppler_mps: np.ndarray


def doppler_bins(radar: RadarConfig, velocity_mps: np.ndarray | None) -> np.ndarray:
    """(M,) int64 — the Doppler bin (signed, in ``[-N/2, N/2)`` of ``N = n_chirps`` bins of
    :attr:`RadarConfig.range_rate_resolution_mps`) of each fine azimuth point's direction
    for a rig moving at ``velocity_mps`` ((3,) radar frame [m/s]): the range rate
    ``-v . u`` of a static scatterer in the horizontal plane at ``u = (sqrt(1 - u_a^2), u_a,
    0)`` (:func:`sim2radar.radar.binning.ArrayGeometry.fine_u`). All zeros for a rig at rest.

    Approximations (docs/radar_model.md): a return's Doppler is that of its arrival direction
    (a multipath return's is ``-v . (u_dep + u_arr) / 2``), and its elevation is taken as 0
    (``cos`` of the +-20 deg elevation field >= 0.94: < 1 bin at walking speed).
    """
    geom = array_geometry(radar)
    if velocity_mps is None or not np.any(np.asarray(velocity_mps)):
        return np.zeros(geom.fine_az, np.int64)
    v = np.asarray(velocity_mps, np.float64).reshape(3)
    u = geom.fine_u
    rate = -(np.sqrt(np.maximum(1.0 - u**2, 0.0)) * v[0] + u * v[1])
    n = radar.n_chirps
    b = np.floor(rate / radar.range_rate_resolution_mps + 0.5).astype(np.int64)
    return np.mod(b + n // 2, n) - n // 2


def detect_frame(acc: Accumulator, radar: RadarConfig, *,
                 velocity_mps: np.ndarray | None = None,
                 rng: np.random.Generator | None = None) -> Detections:
    """Detect one traced frame (:class:`DetectionConfig`): receiver noise from ``rng``
    (None: noise-free, the CFAR on the expected noise), and in the ``integrated`` domain the
    rig's motion (``velocity_mps``, (3,) radar frame [m/s]) separating returns into Doppler
    bins by their direction (:func:`doppler_bins`), as TI's chain separates them on the
    range-Doppler map."""
    geom = array_geometry(radar)
    n0 = cell_noise_power(radar)
    if radar.detection.domain != "integrated":
        aperture = acc.aperture(geom)
        if rng is not None:
            aperture = add_receiver_noise(aperture, geom, n0, rng)
        points = detect_points(None, acc, radar, aperture=aperture, noise_added=rng is not None)
        return Detections(points, np.zeros(len(points), np.float32))
    slabs, apertures = acc.slab_apertures(geom, doppler_bins(radar, velocity_mps))
    return _detect_slabs(slabs, apertures, acc, radar,
                         noise="expected" if rng is None else rng)


def channel_profile(apertures: np.ndarray, geometry) -> np.ndarray:
    """(...) float64 — ``sum |s|^2`` of channel signals ``apertures`` (..., n_z, n_x) over the
    array's channels: the positions holding a virtual element (the grid's other (x, z)
    positions have a signal but no channel, and no receiver noise). TI's detection matrix is
    this sum over the virtual channels (one per position here, with the position's noise
    ``N N0``: :func:`~sim2radar.radar.binning.add_receiver_noise`)."""
    power = apertures.real ** 2 + apertures.imag ** 2
    on = geometry.present.astype(power.dtype)
    return np.einsum("...zx,zx->...", power, on, optimize=False).astype(np.float64)


def _detect_slabs(slabs: np.ndarray, apertures: np.ndarray, acc: Accumulator | None,
                  radar: RadarConfig, noise) -> Detections:
    """TI's chain on the range-Doppler map of the Doppler slabs' channel signals
    (``apertures`` (S, n_range, n_z, n_x) of the signed Doppler bins ``slabs`` (S,)): each
    slab's profile ``sum |s|^2`` over the array's channels (the positions holding a virtual
    element) fills its Doppler column, the others hold receiver
    noise (``noise``: ``"expected"`` its mean, added to the slabs too; ``"none"`` the slabs
    carry it already and the empty columns get its mean; or a Generator to draw it: the
    slabs' receiver noise per present position, ``N N0`` each
    (:func:`~sim2radar.radar.binning.add_receiver_noise`'s model), drawn as the profile needs
    it (:func:`~sim2radar.radar.binning.integrated_power`) and, for the detected cells' rows
    only, in full (:func:`~sim2radar.radar.binning.row_noise`)); a dual-pass CFAR (range,
    then Doppler, a cell must pass both); then in each detected cell the azimuth peaks of its
    slab's map (local maxima over ``min_snr_db`` and within ``sidelobe_level_db`` of the
    cell's strongest)."""
    cfg = radar.detection
    geom = array_geometry(radar)
    n0 = cell_noise_power(radar)
    n_r, n_d = radar.n_range_bins, radar.n_chirps
    present = geom.present
    n_pos = int(present.sum())
    chan_noise = geom.n_elements * n0                       # per position (add_receiver_noise)
    mean_noise = chan_noise * n_pos
    drawn = isinstance(noise, np.random.Generator)
    profile = channel_profile(apertures, geom)                              # (S, n_r)
    if drawn:
        rd = noise.gamma(n_pos, chan_noise, size=(n_r, n_d))  # noise-only Doppler columns
        profile, row_draws = integrated_power(profile, n_pos, chan_noise, noise)
    else:
        rd = np.full((n_r, n_d), mean_noise)
        if noise == "expected":
            profile += mean_noise
    cols = np.mod(slabs, n_d)
    rd[:, cols] = profile.T
    det, _ = cfar.cfar_1d(rd, axis=0, kind=cfg.cfar_kind, guard=cfg.cfar_guard_cells,
                          train=cfg.cfar_training_cells,
                          alpha=10.0 ** (cfg.cfar_threshold_db / 10.0), edges="ti",
                          discard=cfg.cfar_discard_range_bins)
    span = 2 * (cfg.doppler_cfar_guard_cells + cfg.doppler_cfar_training_cells) + 1
    if n_d >= span:
        det_d, _ = cfar.cfar_1d(rd, axis=1, kind=cfg.cfar_kind,
                                guard=cfg.doppler_cfar_guard_cells,
                                train=cfg.doppler_cfar_training_cells,
                                alpha=10.0 ** (cfg.doppler_cfar_threshold_db / 10.0),
                                edges="wrap")
        det &= det_d
    slab_of_col = np.full(n_d, -1)
    slab_of_col[cols] = np.arange(len(slabs))
    ri, ci = np.nonzero(det)
    si = slab_of_col[ci]
    has = si >= 0                          # a noise-only cell cannot pass the minimum SNR
    ri, si = ri[has], si[has]
    if not len(ri):
        return Detections(np.zeros((0, 4), np.float32), np.zeros(0, np.float32))
    rows = apertures[si, ri].astype(np.complex128)                         # (K, n_z, n_x)
    if drawn:
        picked = RowNoise(row_draws.parallel[si, ri], row_draws.rest[si, ri])
        rows[:, present] += row_noise(rows[:, present], picked, noise)
    p = np.abs(azimuth_map(rows, geom).astype(np.complex128)) ** 2          # (K, n_az)
    cand = p > n0 * geom.main_noise_factor * 10.0 ** (cfg.min_snr_db / 10.0)
    if cfg.sidelobe_level_db is not None:
        cand &= p >= p.max(axis=1, keepdims=True) * 10.0 ** (-cfg.sidelobe_level_db / 10.0)
    cand[:, 1:] &= p[:, 1:] >= p[:, :-1]                    # local maxima along azimuth
    cand[:, :-1] &= p[:, :-1] >= p[:, 1:]
    k, ia = np.nonzero(cand)
    points = peak_points(rows[k], ri[k], ia, acc, radar)
    doppler = (slabs[si[k]] * radar.range_rate_resolution_mps).astype(np.float32)
    return Detections(*_strongest_first(points, doppler, radar))


def _strongest_first(points: np.ndarray, doppler: np.ndarray, radar: RadarConfig
                     ) -> tuple[np.ndarray, np.ndarray]:
    order = np.argsort(-points[:, 3], kind="stable")
    points, doppler = points[order], doppler[order]
    if radar.detection.max_points is not None:
        points = points[: radar.detection.max_points]
        doppler = doppler[: radar.detection.max_points]
    return points, doppler


def peak_points(rows: np.ndarray, ir: np.ndarray, ia: np.ndarray, acc: Accumulator | None,
                radar: RadarConfig) -> np.ndarray:
    """(K, 4) float32 points (unsorted) of K azimuth peaks: ``rows`` (K, n_z, n_x) the channel
    signal of each peak's range bin ``ir`` (K,), ``ia`` (K,) its azimuth beam; direction and
    intensity refined on the array response, elevation from the 2D beam, range from the
    power-weighted contributions near the peak (module doc)."""
    geom = array_geometry(radar)
    rng = radar.range_bins_m.astype(np.float64)[ir]
    offsets, step = _offsets(radar.azimuth_bin_u, 1.0)
    ua = _refine_peak(geom.u_az[ia], azimuth_response(rows, geom, geom.u_az[ia], offsets), step)
    ua = np.clip(ua, max(-1.0, geom.u_az[0] - 0.5 * radar.azimuth_bin_u),
                 min(1.0, geom.u_az[-1] + 0.5 * radar.azimuth_bin_u))
    peak_power = np.abs(azimuth_response(rows, geom, ua)[:, 0]) ** 2
    # elevation: the 2D beam at that azimuth over the elevation bins' extent
    el_mid = 0.5 * (geom.u_el[0] + geom.u_el[-1])
    half_span = 0.5 * (geom.u_el[-1] - geom.u_el[0]) / radar.elevation_bin_u + 0.5
    el_off, el_step = _offsets(radar.elevation_bin_u, half_span)
    el_grid = np.clip(el_mid + el_off, -1.0, 1.0)
    if len(ir):
        ue = _refine_peak(np.full(len(ir), el_mid), beam_response(rows, geom, ua, el_grid),
                          el_step)
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
    return np.concatenate([xyz, intensity_db[:, None]], axis=1).astype(np.float32)
