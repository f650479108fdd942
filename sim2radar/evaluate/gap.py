"""The sim–real gap of radar point clouds (paper §4.3, Figure 3, §7.3).

Compares a simulated radar dataset (SIM) with a reference one (REAL: measured radar, or the
project's labelled proxy for it) on what the paper reports: points per frame and their ratio
(the paper's is 12 %: 251 vs 2,057), azimuth and range coverage, an effective azimuth field of
view (the paper's is ~31° simulated vs the radar's 120°), intensity distributions before and
after log-space histogram matching (:mod:`sim2radar.radar.intensity`), and the Chamfer distance
between frames that show the same world from the same pose (a shared frame id).

Everything here is a pure function over arrays except :func:`write_gap_report`, which reads
the two dataset folders it is given, and writes ``gap.json`` and six PNGs into the folder it
is given. Coordinates are the radar frame: x forward, y left, z up [m]; intensities [dB].

Effective azimuth field of view
    The width [deg] of the *smallest* azimuth interval that holds ``fov_coverage`` (95 %) of a
    dataset's points, pooled over its frames (the 95 % highest-density interval of the
    azimuths; computed on the sorted azimuths, not on histogram bins, and on the circle, so an
    interval may wrap through ±180°). It ignores the sparsest 5 % of points (ghosts, multipath at
    wide angles) and does not assume the points are centred on boresight. Points spread
    uniformly over a sector of width W read 0.95 W: a radar that fills its whole 120° field of
    view reads ~114°, a simulation confined to 31° reads ~29.5°; the ratio of the two is the
    ratio of the sectors.

Artefact figures
    Per dataset: the sidelobe share against its control, Doppler, the share beyond 8 m, the
    share below the floor, and the domain its ``dataset.json`` declares. They are defined,
    measured and given their thresholds (:class:`~sim2radar.evaluate.artefacts.ArtefactSettings`,
    held as ``GapSettings.artefacts``) in :mod:`sim2radar.evaluate.artefacts`; this module puts
    both datasets' figures in ``gap.json["artefacts"]`` (:func:`artefacts_dict`) and draws
    ``artefacts.png``.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sim2radar.datasets.openpcdet import DatasetError, read_labels, read_points
from sim2radar.evaluate.artefacts import (
    ArtefactSettings,
    ArtefactStats,
    DatasetInfo,
    artefact_definitions,
    artefact_stats,
    azimuth_deg,
    coverage_fractions,
    doppler_edges,
    doppler_values,
    range_m,
    read_dataset_info,
    stack_points,
)
from sim2radar.evaluate.reconstruction import chamfer_distance
from sim2radar.fileio import atomic_write, jsonable, write_json
from sim2radar.radar.intensity import IntensityMatch, fit_intensity_match

__all__ = [
    "FIGURES",
    "ChamferResult",
    "FovInterval",
    "GapReport",
    "GapSettings",
    "PointCountStats",
    "artefacts_dict",
    "chamfer_pairs",
    "compute_gap",
    "effective_fov",
    "fov_definition",
    "gap_figures",
    "histogram_edges",
    "overlay_png",
    "point_count_stats",
    "write_gap_report",
]

#: Figure names in ``gap.json`` -> file names in the report folder.
FIGURES = {"overlay": "overlay.png", "azimuth": "azimuth.png", "range": "range.png",
           "intensity": "intensity.png", "points": "points.png", "artefacts": "artefacts.png"}

_SIM_COLOR = "tab:red"  # the paper's Figure 3: simulated radar in red
_REAL_COLOR = "tab:blue"  # ... and real radar in blue


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
    """Everything :func:`compute_gap` measures (arrays; :func:`write_gap_report` makes JSON).

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


# --------------------------------------------------------------------------------- figures


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()


def _new_figure(width_in: float, height_in: float):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def overlay_png(
    sim_points: np.ndarray,
    real_points: np.ndarray,
    *,
    title: str,
    boxes: np.ndarray | None = None,
    side_view: bool = True,
    path: str | Path | None = None,
    size_px: int = 800,
) -> bytes:
    """Sim (red) and real (blue) points of one frame on top of each other (paper Figure 3).

    Left: bird's-eye view, x forward up the page, y left to the left (as
    :func:`sim2radar.visualize.bev_png`), the radar as a black triangle at the origin. Right
    (``side_view``): the same x axis up the page against height z [m], so a point sits at the
    same height on the page in both panels.

    Parameters
    ----------
    sim_points, real_points : (N, ≥3), (M, ≥3) float — x, y, z [m] in the radar frame.
    title : str — figure title (e.g. both point counts and their ratio).
    boxes : (K, 7), optional — ``x y z dx dy dz heading`` labels drawn as black outlines.
    side_view : bool — add the x–z panel.
    path : optional — also write the PNG there (parent folders created).
    size_px : int — image height [px].

    Returns
    -------
    bytes — the PNG.
    """
    from matplotlib.patches import Polygon

    from sim2radar.visualize import box_corners_xy

    sp = np.asarray(sim_points, dtype=np.float64).reshape(-1, np.shape(sim_points)[-1])[:, :3]
    rp = np.asarray(real_points, dtype=np.float64).reshape(-1, np.shape(real_points)[-1])[:, :3]
    bxs = np.zeros((0, 7)) if boxes is None else np.asarray(boxes, np.float64).reshape(-1, 7)
    corners = box_corners_xy(bxs)
    allp = np.concatenate([np.zeros((1, 3)), sp, rp])
    pad = 0.5
    x0, x1 = allp[:, 0].min() - pad, allp[:, 0].max() + pad
    y0, y1 = allp[:, 1].min() - pad, allp[:, 1].max() + pad
    if len(corners):
        x0, x1 = min(x0, corners[..., 0].min() - pad), max(x1, corners[..., 0].max() + pad)
        y0, y1 = min(y0, corners[..., 1].min() - pad), max(y1, corners[..., 1].max() + pad)
    z0, z1 = allp[:, 2].min() - pad, allp[:, 2].max() + pad
    if len(bxs):
        z0 = min(z0, float((bxs[:, 2] - bxs[:, 5] / 2).min()) - pad)
        z1 = max(z1, float((bxs[:, 2] + bxs[:, 5] / 2).max()) + pad)
    bev_w = float(np.clip((y1 - y0) / max(x1 - x0, 1e-6), 0.4, 2.5))
    side_w = float(np.clip((z1 - z0) / max(x1 - x0, 1e-6), 0.15, 1.0)) if side_view else 0.0
    h_in = size_px / 100
    fig = _new_figure(h_in * (bev_w + side_w) + 1.0, h_in)
    axes = fig.subplots(1, 2 if side_view else 1, sharey=True, squeeze=False,
                        width_ratios=[bev_w, side_w] if side_view else None)[0]
    ax = axes[0]
    for corner in corners:
        ax.add_patch(Polygon(corner[:, ::-1], closed=True, fill=False, edgecolor="k", lw=1.0,
                             ls="--", zorder=3))
    ax.scatter(rp[:, 1], rp[:, 0], s=3, color=_REAL_COLOR, linewidths=0, alpha=0.6,
               label=f"real ({len(rp):,})", zorder=1)
    ax.scatter(sp[:, 1], sp[:, 0], s=7, color=_SIM_COLOR, linewidths=0, alpha=0.9,
               label=f"sim ({len(sp):,})", zorder=2)
    ax.plot([0], [0], marker="^", color="k", ms=8, ls="none", zorder=4)
    ax.set_xlim(y1, y0)  # +y to the left
    ax.set_ylim(x0, x1)
    ax.set_aspect("equal")
    ax.set_xlabel("y (left) [m]")
    ax.set_ylabel("x (forward) [m]")
    ax.set_title("bird's-eye view", fontsize=9)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(loc="lower right", fontsize=8, markerscale=2)
    if side_view:
        sx = axes[1]
        sx.scatter(rp[:, 2], rp[:, 0], s=3, color=_REAL_COLOR, linewidths=0, alpha=0.6)
        sx.scatter(sp[:, 2], sp[:, 0], s=7, color=_SIM_COLOR, linewidths=0, alpha=0.9)
        sx.plot([0], [0], marker="^", color="k", ms=8, ls="none")
        sx.set_xlim(z0, z1)
        sx.set_aspect("equal")
        sx.set_xlabel("z (up) [m]")
        sx.set_title("side view", fontsize=9)
        sx.grid(True, lw=0.3, alpha=0.5)
    fig.suptitle(title, fontsize=10)
    data = _png(fig)
    _maybe_write(path, data)
    return data


def _maybe_write(path: str | Path | None, data: bytes) -> None:
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, data)


def _steps(ax, edges, frac, **kw) -> None:
    ax.stairs(100 * np.asarray(frac), np.asarray(edges), **kw)


def _azimuth_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    e = rep.azimuth_edges_deg
    for frac, fov, color, name in ((rep.azimuth_real, rep.fov_real, _REAL_COLOR, "real"),
                                   (rep.azimuth_sim, rep.fov_sim, _SIM_COLOR, "sim")):
        _steps(ax, e, frac, color=color,
               label=f"{name}: effective FOV {_fmt(fov.width_deg, '.1f')}°")
        if math.isfinite(fov.width_deg):
            for lo, hi in _unwrap(fov.lo_deg, fov.hi_deg):
                ax.axvspan(lo, hi, color=color, alpha=0.08, lw=0)
    used = np.flatnonzero((rep.azimuth_sim > 0) | (rep.azimuth_real > 0))
    lim = 75.0
    if used.size:
        lim = max(lim, float(np.abs(e[[used[0], used[-1] + 1]]).max()) + 5.0)
    ax.set_xlim(min(lim, 180.0), -min(lim, 180.0))  # +azimuth (left) to the left, as in the BEV
    ax.set_xlabel("azimuth atan2(y, x) [deg] (positive = left)")
    ax.set_ylabel(f"points per {rep.settings.azimuth_bin_deg:g}° bin [%]")
    ax.set_title(f"azimuth coverage (shaded: smallest interval holding "
                 f"{100 * rep.settings.fov_coverage:g} % of points)", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _unwrap(lo: float, hi: float) -> list[tuple[float, float]]:
    """An interval that may run past 180° as one or two pieces inside [-180, 180]."""
    if hi <= 180.0:
        return [(lo, hi)]
    return [(lo, 180.0), (-180.0, hi - 360.0)]


def _range_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    e = rep.range_edges_m
    _steps(ax, e, rep.range_real, color=_REAL_COLOR, label="real")
    _steps(ax, e, rep.range_sim, color=_SIM_COLOR, label="sim")
    ax.set_xlabel("range |(x, y, z)| [m]")
    ax.set_ylabel(f"points per {e[1] - e[0]:g} m bin [%]")
    ax.set_title("range coverage", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _intensity_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    e = rep.intensity_edges_db
    _steps(ax, e, rep.intensity_real, color=_REAL_COLOR, fill=True, alpha=0.35, label="real")
    _steps(ax, e, rep.intensity_sim_before, color=_SIM_COLOR, ls="--", alpha=0.7,
           label="sim (as simulated)")
    _steps(ax, e, rep.intensity_sim_after, color=_SIM_COLOR, label="sim (histogram-matched)")
    ax.set_xlabel("intensity [dB]")
    ax.set_ylabel(f"points per {e[1] - e[0]:.3g} dB bin [%]")
    ax.set_title("intensity distributions (log-space histogram matching)", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _points_png(rep: GapReport) -> bytes:
    fig = _new_figure(8, 4.5)
    ax = fig.subplots()
    top = max(int(rep.sim.counts.max(initial=0)), int(rep.real.counts.max(initial=0)), 1)
    edges = np.linspace(0, top * 1.02 + 1, 41)
    for st, color, name in ((rep.real, _REAL_COLOR, "real"), (rep.sim, _SIM_COLOR, "sim")):
        if st.frames:
            ax.hist(st.counts, bins=edges, color=color, alpha=0.5,
                    label=f"{name}: mean {st.mean:,.0f}, median {st.median:,.0f} "
                          f"({st.frames} frames)")
            ax.axvline(st.mean, color=color, ls="--", lw=1)
    ax.set_xlabel("points per frame")
    ax.set_ylabel("frames")
    ax.set_title(f"points per frame — sim/real density {_pct(rep.points_ratio)}", fontsize=10)
    ax.grid(True, lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    return _png(fig)


def _artefacts_png(rep: GapReport) -> bytes:
    """Three panels: sidelobe share vs its control, Doppler histograms, range > far_range_m
    and below-floor shares; a figure a dataset lacks is written on its panel, not drawn as 0."""
    s = rep.settings.artefacts
    fig = _new_figure(15, 4.8)
    ax_side, ax_dop, ax_share = fig.subplots(1, 3, width_ratios=[1.0, 1.6, 1.1])
    roles = (("sim", rep.artefacts_sim, rep.info_sim, _SIM_COLOR),
             ("real", rep.artefacts_real, rep.info_real, _REAL_COLOR))
    names = [f"{role}\n({_short(info.domain)})" for role, _, info, _ in roles]
    x = np.arange(len(roles))
    w = 0.38
    for k, (_, a, _, color) in enumerate(roles):
        for dx, value, kw, lab in ((-w / 2, a.sidelobe.share, {}, "sidelobe bins"),
                                   (w / 2, a.sidelobe.control_share,
                                    {"hatch": "//", "fill": False}, "control bins")):
            v = 100 * value if math.isfinite(value) else 0.0
            ax_side.bar(x[k] + dx, v, w, color=color, edgecolor=color,
                        label=lab if k == 0 else None, **kw)
            ax_side.annotate(_fmt(100 * value, ".1f"), (x[k] + dx, v), ha="center",
                             va="bottom", fontsize=8)
    tallest = max((100 * v for _, a, _, _ in roles
                   for v in (a.sidelobe.share, a.sidelobe.control_share) if math.isfinite(v)),
                  default=0.0)
    ax_side.set_ylim(0.0, max(tallest, 1.0) * 1.3)  # headroom for the legend
    ax_side.set_xticks(x, names, fontsize=8)
    ax_side.set_ylabel("points [%]")
    ax_side.set_title(f"on a ≥{s.sidelobe_min_drop_db:g} dB stronger return's range bin "
                      f"±{s.sidelobe_range_tolerance_bins}\n(>{s.sidelobe_min_separation_deg:g}° "
                      f"away; control: ±{s.sidelobe_control_offset_bins} bins)", fontsize=9)
    ax_side.legend(fontsize=8, loc="upper right")
    ax_side.grid(True, axis="y", lw=0.3, alpha=0.5)

    missing, top = [], 0.0
    for role, a, _, color in roles:
        if a.doppler is None or rep.doppler_edges_mps is None:
            missing.append(role)
            continue
        _steps(ax_dop, rep.doppler_edges_mps, a.doppler.fraction, color=color,
               label=f"{role}: moving {_fmt(100 * a.doppler.moving_share, '.1f')} %, "
                     f"median |v| {_fmt(a.doppler.abs_median_mps, '.2f')} m/s")
        top = max(top, 100 * float(np.max(a.doppler.fraction, initial=0.0)))
    if rep.doppler_edges_mps is not None:
        ax_dop.legend(fontsize=8, loc="upper left")
        ax_dop.set_yscale("symlog", linthresh=0.1)
        ax_dop.set_ylim(0.0, max(top, 1.0) * 30)  # headroom for the legend (log axis)
    else:
        ax_dop.text(0.5, 0.5, "no Doppler column in either dataset", ha="center",
                    transform=ax_dop.transAxes, fontsize=9)
        ax_dop.set_xticks([])
        ax_dop.set_yticks([])
    ax_dop.set_xlabel("Doppler [m/s]")
    ax_dop.set_ylabel(f"points per {s.doppler_bin_mps:g} m/s bin [%]")
    ax_dop.set_title(f"Doppler (moving: |v| > {s.doppler_bin_mps / 2:g} m/s)"
                     + "".join(f"\n{role}: no Doppler column (not drawn)" for role in missing),
                     fontsize=9)
    ax_dop.grid(True, lw=0.3, alpha=0.5)

    groups = [f"range > {s.far_range_m:g} m", f"> {s.below_floor_margin_m:g} m below floor"]
    gx = np.arange(len(groups))
    for k, (role, a, _, color) in enumerate(roles):
        dx = (k - 0.5) * w
        for g, value in enumerate((a.beyond_range_share, a.below_floor_share)):
            known = value is not None and math.isfinite(value)
            v = 100 * value if known else 0.0
            ax_share.bar(gx[g] + dx, v, w, color=color, label=role if g == 0 else None)
            ax_share.annotate(_fmt(v, ".1f") if known else "unknown", (gx[g] + dx, v),
                              ha="center", va="bottom", fontsize=8,
                              rotation=0 if known else 90)
    ax_share.set_xticks(gx, groups, fontsize=8)
    ax_share.set_ylabel("points [%]")
    ax_share.set_title("range coverage and points below the floor", fontsize=9)
    ax_share.legend(fontsize=8)
    ax_share.grid(True, axis="y", lw=0.3, alpha=0.5)
    return _png(fig)


def _short(text: str, n: int = 28) -> str:
    return text if len(text) <= n else text[:n - 1] + "…"


def gap_figures(rep: GapReport) -> dict[str, bytes]:
    """PNG bytes of the azimuth, range, intensity, points and artefacts figures (keys of
    :data:`FIGURES` less ``overlay``, which needs one frame's points: :func:`overlay_png`)."""
    return {"azimuth": _azimuth_png(rep), "range": _range_png(rep),
            "intensity": _intensity_png(rep), "points": _points_png(rep),
            "artefacts": _artefacts_png(rep)}


def _fmt(v: float, spec: str) -> str:
    return format(v, spec) if v is not None and math.isfinite(v) else "n/a"


def _pct(ratio: float) -> str:
    return f"{100 * ratio:.0f} %" if math.isfinite(ratio) else "n/a"


# ------------------------------------------------------------------------------------ I/O


def _frame_ids(root: Path, role: str) -> list[str]:
    if not root.is_dir():
        raise DatasetError(f"{root}: {role} dataset folder does not exist; pass a folder in "
                           "OpenPCDet's custom layout (points/<id>.npy, labels/<id>.txt, "
                           "ImageSets/{train,val,test}.txt)")
    pts = root / "points"
    if not pts.is_dir():
        raise DatasetError(f"{pts}: {role} dataset has no points/ folder; an OpenPCDet custom "
                           "dataset keeps one (N, 4+) float32 x y z intensity array per frame "
                           "in points/<id>.npy")
    ids = sorted(p.stem for p in pts.glob("*.npy"))
    if not ids:
        raise DatasetError(f"{pts}: {role} dataset has no frames (no points/<id>.npy files)")
    return ids


def _load_points(root: Path, fid: str, role: str) -> np.ndarray:
    path = root / "points" / f"{fid}.npy"
    pts = read_points(path)
    if pts.shape[1] < 4:
        raise DatasetError(f"{path}: {role} points have {pts.shape[1]} columns; the gap report "
                           "needs x y z intensity [dB] (N, 4) or x y z intensity doppler (N, 5)")
    return pts


def _fit_frames(real_root: Path, real_ids: list[str], max_frames: int | None,
                ) -> tuple[list[str], str]:
    """Real frame ids to fit the intensity match on, and a phrase saying which they are."""
    split = real_root / "ImageSets" / "train.txt"
    train = ([s.strip() for s in split.read_text().splitlines() if s.strip()]
             if split.is_file() else [])
    if train:
        ids = train[:max_frames] if max_frames else train
        limited = f", first {len(ids)} of {len(train)}" if len(ids) < len(train) else ""
        return ids, f"REAL train split ({split}{limited})"
    why = "no ImageSets/train.txt" if not split.is_file() else "ImageSets/train.txt is empty"
    return real_ids, f"all analysed REAL frames ({why}: no train split to fit on)"


def write_gap_report(
    sim_root: str | Path,
    real_root: str | Path,
    out_dir: str | Path,
    *,
    max_frames: int | None = None,
    overlay_frame: str | None = None,
    settings: GapSettings | None = None,
) -> dict[str, Any]:
    """Compare two datasets in OpenPCDet's custom layout; write ``gap.json`` and six PNGs.

    Reads ``SIM/points/*.npy`` and ``REAL/points/*.npy`` (x y z [m], intensity [dB], optional
    Doppler), fits :func:`~sim2radar.radar.intensity.fit_intensity_match` from all analysed sim
    intensities to those of the REAL **train** split (``REAL/ImageSets/train.txt``; with no
    train split, all analysed REAL frames, and ``intensity.fitted_on`` says so), measures
    :func:`compute_gap` (with each folder's ``dataset.json``:
    :func:`~sim2radar.evaluate.artefacts.read_dataset_info`), and
    writes into ``out_dir``: ``gap.json``, ``overlay.png``, ``azimuth.png``, ``range.png``,
    ``intensity.png``, ``points.png``, ``artefacts.png``.

    Parameters
    ----------
    sim_root, real_root : dataset folders (SIM: simulated; REAL: measured or the reference
        radar's proxy). Frames are the ``points/*.npy`` files, sorted by id; labels are read
        only for the overlay frame (drawn when present).
    out_dir : report folder (created).
    max_frames : analyse at most the first N frame ids (sorted) of each dataset, and fit the
        intensity match on at most the first N train ids.
    overlay_frame : frame id to overlay; default: the shared frame with the median Chamfer
        distance (a typical frame, not the best one), or, with no shared id, the first frame
        of each dataset (the title then says they are different scenes).
    settings : binning, the FOV definition and the artefact thresholds.

    Returns
    -------
    dict — the content of ``gap.json`` (NaN written as null)::

        {"sim": {"root", "domain", "frames", "points_per_frame_mean",
                 "points_per_frame_median"},
         "real": {...}, "points_ratio",
         "azimuth": {"edges_deg", "sim_fraction", "real_fraction",
                     "effective_fov_deg": {"sim", "real"}, "definition"},
         "range": {"edges_m", "sim_fraction", "real_fraction"},
         "intensity": {"edges_db", "sim_before", "sim_after", "real", "fitted_on", "match"},
         "chamfer": {"pairs", "mean_m", "per_frame": {id: m}} or null,
         "overlay_frame": id or null,
         "artefacts": {"settings", "definitions", "doppler_edges_mps", "sim", "real"}
                      (:func:`artefacts_dict`),
         "figures": {"overlay": "overlay.png", ...}}

    Raises
    ------
    DatasetError (a ValueError) — a missing folder or malformed file, named with the fix.
    """
    s = settings or GapSettings()
    if max_frames is not None and max_frames < 1:
        raise ValueError(f"max_frames must be >= 1, got {max_frames}")
    sim_root, real_root, out_dir = Path(sim_root), Path(real_root), Path(out_dir)
    sim_ids = _frame_ids(sim_root, "SIM")[:max_frames]
    real_ids = _frame_ids(real_root, "REAL")[:max_frames]
    sim = {fid: _load_points(sim_root, fid, "SIM") for fid in sim_ids}
    real = {fid: _load_points(real_root, fid, "REAL") for fid in real_ids}

    fit_ids, fitted_where = _fit_frames(real_root, real_ids, max_frames)
    fit_real = [real[f] if f in real else _load_points(real_root, f, "REAL") for f in fit_ids]
    src = np.concatenate([p[:, 3] for p in sim.values()])
    tgt = np.concatenate([p[:, 3] for p in fit_real]) if fit_real else np.zeros(0)
    if src.size == 0:
        raise DatasetError(f"{sim_root / 'points'}: all {len(sim)} analysed SIM frames are "
                           "empty; nothing to compare (check the simulation's output)")
    if tgt.size == 0:
        raise DatasetError(f"{real_root}: the {len(fit_ids)} REAL frames to fit intensity "
                           f"matching on ({fitted_where}) have no points; list frames with "
                           "points in ImageSets/train.txt")
    match = fit_intensity_match(src, tgt)
    fitted_on = (f"{fitted_where}: {len(fit_ids)} frames, {tgt.size:,} points; "
                 f"source: all {len(sim)} analysed SIM frames, {src.size:,} points")

    rep = compute_gap(sim, real, match, s, sim_info=read_dataset_info(sim_root),
                      real_info=read_dataset_info(real_root))

    out_dir.mkdir(parents=True, exist_ok=True)
    chosen = _overlay_choice(rep, overlay_frame, sim, real)
    if chosen is not None:
        sim_pts, real_pts = sim[chosen], real[chosen]
        label = real_root / "labels" / f"{chosen}.txt"
        boxes = read_labels(label)[0] if label.is_file() else None
        title = (f"frame {chosen}: real {len(real_pts):,} points (blue), sim {len(sim_pts):,} "
                 f"points (red); density {_pct(len(sim_pts) / max(len(real_pts), 1))}")
    else:
        sim_id, real_id = sim_ids[0], real_ids[0]
        sim_pts, real_pts, boxes = sim[sim_id], real[real_id], None
        title = (f"different scenes (no shared frame id): real {real_id} {len(real_pts):,} "
                 f"points (blue), sim {sim_id} {len(sim_pts):,} points (red); "
                 f"density {_pct(len(sim_pts) / max(len(real_pts), 1))}")
    overlay_png(sim_pts, real_pts, title=title, boxes=boxes, path=out_dir / FIGURES["overlay"])
    for name, data in gap_figures(rep).items():
        atomic_write(out_dir / FIGURES[name], data)

    doc = jsonable({
        "sim": _dataset_dict(sim_root, rep.sim, rep.info_sim),
        "real": _dataset_dict(real_root, rep.real, rep.info_real),
        "points_ratio": rep.points_ratio,
        "azimuth": {"edges_deg": rep.azimuth_edges_deg, "sim_fraction": rep.azimuth_sim,
                    "real_fraction": rep.azimuth_real,
                    "effective_fov_deg": {"sim": rep.fov_sim.width_deg,
                                          "real": rep.fov_real.width_deg},
                    "definition": fov_definition(s.fov_coverage)},
        "range": {"edges_m": rep.range_edges_m, "sim_fraction": rep.range_sim,
                  "real_fraction": rep.range_real},
        "intensity": {"edges_db": rep.intensity_edges_db, "sim_before": rep.intensity_sim_before,
                      "sim_after": rep.intensity_sim_after, "real": rep.intensity_real,
                      "fitted_on": fitted_on, "match": match.to_dict()},
        "chamfer": None if rep.chamfer is None else {
            "pairs": rep.chamfer.pairs, "mean_m": rep.chamfer.mean_m,
            "per_frame": dict(rep.chamfer.per_frame)},
        "overlay_frame": chosen,
        "artefacts": artefacts_dict(rep),
        "figures": dict(FIGURES),
    })
    write_json(out_dir / "gap.json", doc)
    return doc


def _dataset_dict(root: Path, st: PointCountStats, info: DatasetInfo) -> dict[str, Any]:
    return {"root": str(root), "domain": info.domain, "frames": st.frames,
            "points_per_frame_mean": st.mean, "points_per_frame_median": st.median}


def artefacts_dict(rep: GapReport) -> dict[str, Any]:
    """``gap.json["artefacts"]`` (NaN left in; :func:`write_gap_report` writes it as null;
    ``settings`` is ``rep.settings.artefacts``, an
    :class:`~sim2radar.evaluate.artefacts.ArtefactSettings`, field by field)::

        {"settings": {"range_resolution_m", "sidelobe_min_drop_db",
                      "sidelobe_min_separation_deg", "sidelobe_range_tolerance_bins",
                      "sidelobe_control_offset_bins", "doppler_bin_mps", "far_range_m",
                      "below_floor_margin_m"},
         "definitions": {"sidelobe", "doppler", "beyond_range", "below_floor"},
         "doppler_edges_mps": [...] or null,
         "sim": {"points", "range_resolution_m", "range_resolution_from",
                 "sidelobe_share", "sidelobe_control_share", "sidelobe_difference",
                 "sidelobe_points", "sidelobe_control_points": {"plus", "minus", "either"},
                 "doppler": {"fraction", "moving_share", "abs_median_mps"} or null,
                 "doppler_note": str or null,
                 "beyond_range_share",
                 "below_floor_share": float or null, "radar_height_m": float or null,
                 "below_floor_note": str or null},
         "real": {...}}
    """
    s = rep.settings.artefacts
    doc: dict[str, Any] = {
        "settings": asdict(s),
        "definitions": artefact_definitions(s),
        "doppler_edges_mps": rep.doppler_edges_mps,
    }
    for role, a in (("sim", rep.artefacts_sim), ("real", rep.artefacts_real)):
        doc[role] = {
            "points": a.points,
            "range_resolution_m": a.range_resolution_m,
            "range_resolution_from": a.range_resolution_from,
            "sidelobe_share": a.sidelobe.share,
            "sidelobe_control_share": a.sidelobe.control_share,
            "sidelobe_difference": a.sidelobe.difference,
            "sidelobe_points": a.sidelobe.on_sidelobe,
            "sidelobe_control_points": {"plus": a.sidelobe.on_control_plus,
                                        "minus": a.sidelobe.on_control_minus,
                                        "either": a.sidelobe.on_control_either},
            "doppler": None if a.doppler is None else {
                "fraction": a.doppler.fraction, "moving_share": a.doppler.moving_share,
                "abs_median_mps": a.doppler.abs_median_mps},
            "doppler_note": a.doppler_note,
            "beyond_range_share": a.beyond_range_share,
            "below_floor_share": a.below_floor_share,
            "radar_height_m": a.radar_height_m,
            "below_floor_note": a.below_floor_note,
        }
    return doc


def _overlay_choice(rep: GapReport, requested: str | None, sim: Mapping[str, np.ndarray],
                    real: Mapping[str, np.ndarray]) -> str | None:
    if requested is not None:
        missing = [name for name, frames in (("SIM", sim), ("REAL", real))
                   if requested not in frames]
        if missing:
            raise DatasetError(f"overlay frame {requested!r} is not among the analysed frames of "
                               f"{' and '.join(missing)}; pick an id present in both points/ "
                               "folders (or raise --max-frames)")
        return requested
    if rep.chamfer is None:
        return None
    finite = [(d, fid) for fid, d in rep.chamfer.per_frame.items() if math.isfinite(d)]
    if not finite:
        return rep.shared_ids[0]
    finite.sort()
    return finite[(len(finite) - 1) // 2][1]
