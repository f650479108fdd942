"""The measures of the sim–real gap report: settings, result types and the pure functions.

What :func:`compute_gap` measures on two sets of frames (SIM: a simulated radar dataset;
REAL: measured radar, or the project's labelled proxy for it), as the paper reports it (§4.3,
Figure 3, §7.3): points per frame and their ratio (the paper's is 12 %: 251 vs 2,057), azimuth
and range coverage, an effective azimuth field of view (the paper's is ~31° simulated vs the
radar's 120°), intensity distributions before and after log-space histogram matching
(:mod:`sim2radar.radar.intensity`), the Chamfer distance between frames that show the same world
from the same pose (a shared frame id), and the artefact figures of
:mod:`sim2radar.evaluate.artefacts`. Everything here is a pure function over arrays; the figures
are drawn by :mod:`sim2radar.evaluate.gap_figures`, the report folder is written by
:mod:`sim2radar.evaluate.gap` (which re-exports every public name of this module).
Coordinates are the radar frame: x forward, y left, z up [m]; intensities [dB].

Effective azimuth field of view
    The width [deg] of the *smallest* azimuth interval that holds ``fov_coverage`` (95 %) of a
    dataset's points, pooled over its frames (the 95 % highest-density interval of the
    azimuths; computed on the sorted azimuths, not on histogram bins, and on the circle, so an
    interval may wrap through ±180°). It ignores the sparsest 5 % of points (ghosts, multipath at
    wide angles) and does not assume the points are centred on boresight. Points spread
    uniformly over a sector of width W read 0.95 W: a radar that fills its whole 120° field of
    view reads ~114°, a simulation confined to 31° reads ~29.5°; the ratio of the two is the
    ratio of the sectors.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from sim2radar.evaluate.artefacts import (
    ArtefactSettings,
    ArtefactStats,
    DatasetInfo,
    artefact_stats,
    azimuth_deg,
    coverage_fractions,
    doppler_edges,
    doppler_values,
    range_m,
    stack_points,
)
from sim2radar.evaluate.reconstruction import chamfer_distance
from sim2radar.radar.intensity import IntensityMatch

__all__ = [
    "ChamferResult",
    "FovInterval",
    "GapReport",
    "GapSettings",
    "PointCountStats",
    "chamfer_pairs",
    "compute_gap",
    "effective_fov",
    "fov_definition",
    "histogram_edges",
    "point_count_stats",
]


@dataclass(frozen=True)
class GapSettings:
    """Binning, the field-of-view definition and the artefact thresholds of a gap report.

    Attributes
    ----------
    azimuth_bin_deg : float [deg] — azimuth histogram bin width over [-180°, 180°] (rounded
        so the bins tile the circle); 2° is about two azimuth resolution cells of the TI
        cascade (1.18°).
    range_bin_m : float [m] — range histogram bin width from 0 to the farthest point (widened
        so there are at most ``max_bins`` bins).
    intensity_bin_db : float [dB] — intensity histogram bin width over the span of all three
        distributions; narrowed so the central 99 % of the real intensities spans at least
        ``min_real_bins`` bins (intensities on a narrow scale, e.g. 0–1), then widened so
        there are at most ``max_bins`` bins.
    min_real_bins : int — see ``intensity_bin_db``.
    max_bins : int — cap on range, intensity and Doppler bins (far outliers or two very
        different dB scales would otherwise make thousands of empty bins).
    fov_coverage : float in (0, 1] — share of points the effective azimuth FOV must hold.
    artefacts : :class:`~sim2radar.evaluate.artefacts.ArtefactSettings` — thresholds of the
        artefact figures (sidelobe share, Doppler bins, range beyond, below the floor), each
        with its unit there; ``gap.json["artefacts"]["settings"]`` is these fields.
    """

    azimuth_bin_deg: float = 2.0
    range_bin_m: float = 0.25
    intensity_bin_db: float = 1.0
    min_real_bins: int = 40
    max_bins: int = 200
    fov_coverage: float = 0.95
    artefacts: ArtefactSettings = ArtefactSettings()

    def __post_init__(self) -> None:
        for name in ("azimuth_bin_deg", "range_bin_m", "intensity_bin_db"):
            if not getattr(self, name) > 0:
                raise ValueError(f"GapSettings.{name} must be > 0, got {getattr(self, name)}")
        if not 0 < self.fov_coverage <= 1:
            raise ValueError(f"GapSettings.fov_coverage must be in (0, 1], got {self.fov_coverage}")
        if self.max_bins < 1:
            raise ValueError(f"GapSettings.max_bins must be >= 1, got {self.max_bins}")
        if not isinstance(self.artefacts, ArtefactSettings):
            raise TypeError(f"GapSettings.artefacts must be an ArtefactSettings, got "
                            f"{type(self.artefacts).__name__}")


@dataclass(frozen=True)
class PointCountStats:
    """Points per frame of one dataset.

    Attributes
    ----------
    frames : int — number of frames.
    mean, median : float — points per frame (NaN with no frames).
    counts : (F,) int64 — points in each frame.
    """

    frames: int
    mean: float
    median: float
    counts: np.ndarray


@dataclass(frozen=True)
class FovInterval:
    """The smallest azimuth interval holding a share of the points.

    Attributes
    ----------
    lo_deg, hi_deg : float [deg] — interval ends (``hi_deg`` may exceed 180° when the interval
        wraps through ±180°); NaN with no points.
    width_deg : float [deg] — ``hi_deg - lo_deg``, the effective field of view.
    coverage : float — the share of points it was asked to hold.
    """

    lo_deg: float
    hi_deg: float
    width_deg: float
    coverage: float


@dataclass(frozen=True)
class ChamferResult:
    """Chamfer distances of frames present in both datasets.

    Attributes
    ----------
    per_frame : {frame id: Chamfer distance [m]} — NaN where either frame has no points.
    mean_m : float [m] — mean over the frames with a finite distance (NaN if none).
    """

    per_frame: dict[str, float]
    mean_m: float

    @property
    def pairs(self) -> int:
        return len(self.per_frame)


@dataclass(frozen=True)
class GapReport:
    """Everything :func:`compute_gap` measures (arrays;
    :func:`~sim2radar.evaluate.gap.write_gap_report` makes JSON).

    Attributes
    ----------
    sim, real : :class:`PointCountStats` — points per frame.
    points_ratio : float — mean sim points per frame / mean real points per frame.
    azimuth_edges_deg : (A + 1,) float64 [deg] — azimuth bin edges (atan2(y, x)).
    azimuth_sim, azimuth_real : (A,) float64 — fraction of all points in each bin.
    fov_sim, fov_real : :class:`FovInterval` — effective azimuth field of view.
    range_edges_m : (R + 1,) float64 [m] — range bin edges (|(x, y, z)|).
    range_sim, range_real : (R,) float64 — fraction of all points in each bin.
    intensity_edges_db : (I + 1,) float64 [dB] — intensity bin edges.
    intensity_sim_before, intensity_sim_after, intensity_real : (I,) float64 — fraction of
        points in each bin: sim as simulated, sim after ``match``, real.
    match : :class:`~sim2radar.radar.intensity.IntensityMatch` — the sim -> real map used.
    chamfer : :class:`ChamferResult` or None — None when no frame id is in both datasets.
    shared_ids : tuple of str — frame ids in both datasets (sorted).
    settings : :class:`GapSettings`.
    doppler_edges_mps : (D + 1,) float64 [m/s] or None — Doppler bin edges over both
        datasets' span, bins centred on 0 (None when neither has a Doppler column).
    artefacts_sim, artefacts_real : :class:`~sim2radar.evaluate.artefacts.ArtefactStats`.
    info_sim, info_real : :class:`~sim2radar.evaluate.artefacts.DatasetInfo` — what each
        ``dataset.json`` said.
    """

    sim: PointCountStats
    real: PointCountStats
    points_ratio: float
    azimuth_edges_deg: np.ndarray
    azimuth_sim: np.ndarray
    azimuth_real: np.ndarray
    fov_sim: FovInterval
    fov_real: FovInterval
    range_edges_m: np.ndarray
    range_sim: np.ndarray
    range_real: np.ndarray
    intensity_edges_db: np.ndarray
    intensity_sim_before: np.ndarray
    intensity_sim_after: np.ndarray
    intensity_real: np.ndarray
    match: IntensityMatch
    chamfer: ChamferResult | None
    shared_ids: tuple[str, ...]
    settings: GapSettings
    doppler_edges_mps: np.ndarray | None
    artefacts_sim: ArtefactStats
    artefacts_real: ArtefactStats
    info_sim: DatasetInfo
    info_real: DatasetInfo


# --------------------------------------------------------------------------- pure measures


def point_count_stats(counts: Sequence[int] | np.ndarray) -> PointCountStats:
    """Mean and median points per frame of ``counts`` ((F,) points in each frame)."""
    c = np.asarray(counts, dtype=np.int64).ravel()
    if c.size == 0:
        return PointCountStats(0, float("nan"), float("nan"), c)
    return PointCountStats(int(c.size), float(c.mean()), float(np.median(c)), c)


def histogram_edges(lo: float, hi: float, step: float, max_bins: int = 200) -> np.ndarray:
    """Bin edges from ``floor(lo / step) * step`` to at least ``hi`` in steps of ``step``.

    The step is widened (doubled until it fits) so there are at most ``max_bins`` bins; an
    empty or degenerate span gets one bin of width ``step``. Returns (B + 1,) float64.
    """
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi < lo:
        lo, hi = 0.0, step
    while (hi - lo) / step > max_bins:
        step *= 2.0
    start = math.floor(lo / step) * step
    n = max(1, math.ceil((hi - start) / step - 1e-9))
    if start + n * step <= hi:  # the maximum must fall inside the last (closed) bin
        n += 1
    return start + step * np.arange(n + 1, dtype=np.float64)


def effective_fov(azimuths_deg: np.ndarray, coverage: float = 0.95) -> FovInterval:
    """The smallest azimuth interval holding ``coverage`` of the points (module docstring).

    Exact on the sorted azimuths: with n points and k = ceil(coverage · n), the width of the
    interval from point i to point i + k - 1 (indices taken around the circle, adding 360° when
    they wrap) is minimised over i. Points spread uniformly over a sector of width W give
    ≈ coverage · W.

    Parameters
    ----------
    azimuths_deg : (N,) float [deg] — e.g. :func:`azimuth_deg` of a dataset's points.
    coverage : float in (0, 1].

    Returns
    -------
    :class:`FovInterval` (NaN ends and width with no points).
    """
    if not 0 < coverage <= 1:
        raise ValueError(f"coverage must be in (0, 1], got {coverage}")
    a = np.sort(np.mod(np.asarray(azimuths_deg, dtype=np.float64).ravel() + 180.0, 360.0) - 180.0)
    n = a.size
    if n == 0:
        return FovInterval(float("nan"), float("nan"), float("nan"), float(coverage))
    k = min(n, max(1, math.ceil(coverage * n - 1e-9)))
    circle = np.concatenate([a, a + 360.0])
    widths = circle[k - 1:k - 1 + n] - circle[:n]
    i = int(np.argmin(widths))
    lo, hi = float(circle[i]), float(circle[i + k - 1])
    return FovInterval(lo, hi, hi - lo, float(coverage))


def fov_definition(coverage: float = 0.95) -> str:
    """The sentence ``gap.json`` carries to say what ``effective_fov_deg`` means."""
    pct = f"{100 * coverage:g} %"
    return (f"width [deg] of the smallest azimuth interval (azimuth = atan2(y, x), x forward, "
            f"y left) holding {pct} of the dataset's points pooled over its frames "
            f"({pct} highest-density interval, exact on the sorted azimuths, not binned); points "
            f"spread uniformly over a sector of width W read {coverage:g} W")


def chamfer_pairs(sim: Mapping[str, np.ndarray],
                  real: Mapping[str, np.ndarray]) -> ChamferResult | None:
    """Symmetric Chamfer distance of every frame id present in both datasets.

    Frames with the same id show the same world from the same radar pose, so their points are
    in the same radar frame. The distance is
    :func:`sim2radar.evaluate.reconstruction.chamfer_distance` (½ of the two mean
    nearest-neighbour distances, scipy ``cKDTree``, x y z only).

    Parameters
    ----------
    sim, real : {frame id: (N, ≥3) float points [m]}.

    Returns
    -------
    :class:`ChamferResult` over the shared ids (sorted), or None if no id is shared.
    """
    shared = sorted(set(sim) & set(real))
    if not shared:
        return None
    per = {fid: chamfer_distance(sim[fid], real[fid]) for fid in shared}
    finite = [d for d in per.values() if math.isfinite(d)]
    return ChamferResult(per, float(np.mean(finite)) if finite else float("nan"))


def compute_gap(
    sim: Mapping[str, np.ndarray],
    real: Mapping[str, np.ndarray],
    match: IntensityMatch,
    settings: GapSettings | None = None,
    *,
    sim_info: DatasetInfo | None = None,
    real_info: DatasetInfo | None = None,
) -> GapReport:
    """Measure the sim–real gap between two sets of frames.

    Parameters
    ----------
    sim, real : {frame id: (N, ≥4) float32 points} — x, y, z [m] (radar frame), intensity
        [dB], optional Doppler [m/s] as the 5th column (used only by the artefact figures),
        further columns ignored.
    match : the sim -> real intensity map (fit it on the real *training* frames only).
    settings : binning, FOV definition and artefact thresholds (defaults: :class:`GapSettings`).
    sim_info, real_info : what each dataset's ``dataset.json`` says
        (:func:`~sim2radar.evaluate.artefacts.read_dataset_info`;
        default: nothing declared — domain "undeclared", default range resolution, floor
        unknown).

    Returns
    -------
    :class:`GapReport`
    """
    s = settings or GapSettings()
    for name, frames in (("sim", sim), ("real", real)):
        for fid, p in frames.items():
            if np.ndim(p) != 2 or np.shape(p)[1] < 4:
                raise ValueError(f"{name} frame {fid}: points must be (N, >=4) x y z intensity, "
                                 f"got shape {np.shape(p)}")
    sim_all = stack_points(sim)
    real_all = stack_points(real)
    sim_stats = point_count_stats([len(p) for p in sim.values()])
    real_stats = point_count_stats([len(p) for p in real.values()])
    ratio = (sim_stats.mean / real_stats.mean
             if real_stats.frames and sim_stats.frames and real_stats.mean > 0 else float("nan"))

    az_edges = np.linspace(-180.0, 180.0, max(1, round(360.0 / s.azimuth_bin_deg)) + 1)
    az_sim, az_real = azimuth_deg(sim_all), azimuth_deg(real_all)

    r_sim, r_real = range_m(sim_all), range_m(real_all)
    r_max = float(max(r_sim.max(initial=0.0), r_real.max(initial=0.0)))
    r_edges = histogram_edges(0.0, r_max, s.range_bin_m, s.max_bins)

    i_before = sim_all[:, 3].astype(np.float64)
    i_after = match.apply(i_before).astype(np.float64) if i_before.size else i_before
    i_real = real_all[:, 3].astype(np.float64)
    everything = np.concatenate([i_before, i_after, i_real])
    i_step = s.intensity_bin_db
    if i_real.size:
        spread = float(np.subtract(*np.quantile(i_real, [0.995, 0.005])))
        if spread > 0:
            i_step = min(i_step, spread / max(s.min_real_bins, 1))
    i_edges = (histogram_edges(float(everything.min()), float(everything.max()), i_step,
                               s.max_bins)
               if everything.size else histogram_edges(0.0, 0.0, i_step))

    chamfer = chamfer_pairs(sim, real)
    sim_info, real_info = sim_info or DatasetInfo(), real_info or DatasetInfo()
    dops = [d for d in (doppler_values(sim)[0], doppler_values(real)[0]) if d is not None]
    d_edges = doppler_edges(dops, s.artefacts.doppler_bin_mps, s.max_bins)
    return GapReport(
        sim=sim_stats, real=real_stats, points_ratio=float(ratio),
        azimuth_edges_deg=az_edges,
        azimuth_sim=coverage_fractions(az_sim, az_edges),
        azimuth_real=coverage_fractions(az_real, az_edges),
        fov_sim=effective_fov(az_sim, s.fov_coverage),
        fov_real=effective_fov(az_real, s.fov_coverage),
        range_edges_m=r_edges,
        range_sim=coverage_fractions(r_sim, r_edges),
        range_real=coverage_fractions(r_real, r_edges),
        intensity_edges_db=i_edges,
        intensity_sim_before=coverage_fractions(i_before, i_edges),
        intensity_sim_after=coverage_fractions(i_after, i_edges),
        intensity_real=coverage_fractions(i_real, i_edges),
        match=match,
        chamfer=chamfer,
        shared_ids=tuple(sorted(set(sim) & set(real))),
        settings=s,
        doppler_edges_mps=d_edges,
        artefacts_sim=artefact_stats(sim, sim_info, s.artefacts, d_edges, max_bins=s.max_bins),
        artefacts_real=artefact_stats(real, real_info, s.artefacts, d_edges,
                                      max_bins=s.max_bins),
        info_sim=sim_info,
        info_real=real_info,
    )
