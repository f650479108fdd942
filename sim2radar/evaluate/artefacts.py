"""Artefact figures of a radar point-cloud dataset (the sim–real gap report's artefacts section).

What a radar chain leaves in its point clouds, measured the same way on a simulated and a
reference dataset (:func:`artefact_stats`, one dataset at a time; thresholds are
:class:`ArtefactSettings`). :mod:`sim2radar.evaluate.gap` puts the figures of both in
``gap.json["artefacts"]`` and draws ``artefacts.png``.

- *domain*: the ``domain`` string of the dataset's ``dataset.json``, else "undeclared".
- *sidelobe share*: the share of points on the range bin ±1 of a return at least 13 dB
  stronger and more than 3° away in azimuth, in the same frame (:func:`sidelobe_flags`):
  where the angle sidelobes of that return fall (a beamformer's sidelobes appear at the
  source's range, across azimuth). Its *control* is the same count on the bins +5 (±1)
  and on the bins -5 (±1) instead, averaged (each window as wide as the sidelobe one): the
  chance rate. A dataset that keeps sidelobe arcs as points reads far above its control,
  a clean one within a few points of it. (Counting a point once when either offset window
  holds a stronger return would double the window and overstate chance: 47 % vs a 34 %
  share on uniformly scattered points, 200 a frame.) Range bins are
  floor(range / range_resolution_m + 0.5) with range_resolution_m from ``dataset.json``
  (else the TI cascade's c/2B, 0.038 m).
- *Doppler* (5th point column, [m/s]): a histogram in 0.1 m/s bins centred on 0 over both
  datasets' span, the share of points with |Doppler| > half a bin, the |Doppler| median;
  null with a note, never zeros, when the points have no 5th column.
- *range beyond 8 m*: the share of points with |(x, y, z)| > 8 m.
- *points below the floor*: the share more than 0.1 m below z = -radar_height_m (the floor
  in the radar frame; ``radar_height_m`` from ``dataset.json``); null with a note when the
  dataset does not say how high its radar is.

Everything here is a pure function over arrays except :func:`read_dataset_info`, which reads
a dataset's ``dataset.json``. Coordinates are the radar frame: x forward, y left, z up [m];
intensities [dB]; Doppler [m/s]. The point geometry the gap report also uses
(:func:`azimuth_deg`, :func:`range_m`, :func:`coverage_fractions`, :func:`stack_points`) is
defined here, so that this module needs nothing from :mod:`sim2radar.evaluate.gap`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sim2radar.datasets.openpcdet import METADATA_FILE, UNDECLARED, DatasetError, read_metadata

__all__ = [
    "DEFAULT_RESOLUTION_FROM",
    "UNDECLARED",
    "ArtefactSettings",
    "ArtefactStats",
    "DatasetInfo",
    "DopplerStats",
    "SidelobeShare",
    "artefact_definitions",
    "artefact_stats",
    "azimuth_deg",
    "coverage_fractions",
    "doppler_edges",
    "doppler_stats",
    "doppler_values",
    "range_bins",
    "range_m",
    "read_dataset_info",
    "sidelobe_flags",
    "sidelobe_share",
    "stack_points",
]

#: ``range_resolution_from`` when ``dataset.json`` gives no range resolution and
#: :attr:`ArtefactSettings.range_resolution_m` is used (``GapSettings.artefacts`` holds it).
DEFAULT_RESOLUTION_FROM = "GapSettings default"


@dataclass(frozen=True)
class ArtefactSettings:
    """Thresholds and defaults of the artefact figures (module docstring).

    Attributes
    ----------
    range_resolution_m : float [m] — range bin width of a dataset whose ``dataset.json`` has no
        ``range_resolution_m``: c / (2 B) of the TI cascade (preset ``ti-mmwcas``,
        B = 3.95 GHz: 0.0379 m).
    sidelobe_min_drop_db : float [dB] — a point counts as a possible angle sidelobe of a
        return at least this much stronger: 13 dB is the highest sidelobe of a uniformly
        weighted aperture (-13.26 dB; Harris 1978, Proc. IEEE 66(1), Table I, rectangular
        window), the strongest an unwindowed array beamformer makes.
    sidelobe_min_separation_deg : float [deg] — ... and more than this far from it in azimuth
        (wrapped |Δ atan2(y, x)|): 3° is about 2.5 azimuth resolution cells of the TI cascade
        (1.18°), outside the stronger return's main lobe.
    sidelobe_range_tolerance_bins : int [range bins] — ... and on its range bin ± this many
        (a sidelobe sits at its source's range; ±1 absorbs the peak interpolation).
    sidelobe_control_offset_bins : int [range bins] — the control counts the same stronger
        returns on the bins ± this offset (± the tolerance) instead: the rate at which a
        stronger return is near a point by chance. Must exceed twice the tolerance so the
        control windows do not overlap the sidelobe window.
    doppler_bin_mps : float [m/s] — Doppler histogram bin width, bins centred on 0; a point
        "moves" when |Doppler| > half a bin (outside the zero bin).
    far_range_m : float [m] — range coverage: the share of points with range > this.
    below_floor_margin_m : float [m] — a point is below the floor when it is more than this
        below z = -radar_height_m (the floor in the radar frame).
    """

    range_resolution_m: float = 0.038
    sidelobe_min_drop_db: float = 13.0
    sidelobe_min_separation_deg: float = 3.0
    sidelobe_range_tolerance_bins: int = 1
    sidelobe_control_offset_bins: int = 5
    doppler_bin_mps: float = 0.1
    far_range_m: float = 8.0
    below_floor_margin_m: float = 0.1

    def __post_init__(self) -> None:
        for name in ("range_resolution_m", "sidelobe_min_drop_db", "doppler_bin_mps"):
            if not getattr(self, name) > 0:
                raise ValueError(f"ArtefactSettings.{name} must be > 0, got {getattr(self, name)}")
        for name in ("sidelobe_min_separation_deg", "far_range_m", "below_floor_margin_m",
                     "sidelobe_range_tolerance_bins"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"ArtefactSettings.{name} must be >= 0, got {getattr(self, name)}")
        if self.sidelobe_control_offset_bins <= 2 * self.sidelobe_range_tolerance_bins:
            raise ValueError(
                f"ArtefactSettings.sidelobe_control_offset_bins "
                f"({self.sidelobe_control_offset_bins}) must exceed twice "
                f"sidelobe_range_tolerance_bins ({self.sidelobe_range_tolerance_bins}), or the "
                "control windows overlap the sidelobe window")


@dataclass(frozen=True)
class DatasetInfo:
    """What a dataset's ``dataset.json`` says that the artefact figures need.

    Attributes
    ----------
    domain : str — its ``domain`` string, or ``"undeclared"`` (never guessed).
    range_resolution_m : float or None [m] — its ``range_resolution_m``.
    radar_height_m : float or None [m] — its ``radar_height_m``: the radar's height above the
        floor (the floor is at z = -radar_height_m in the radar frame).
    point_geometry, labels_vs_truth : dict or None — its ``point_geometry`` and
        ``labels_vs_truth`` (what the factory measured against the true geometry of procedural
        worlds, :func:`sim2radar.factory.export.export_frames`); None when absent.
    """

    domain: str = UNDECLARED
    range_resolution_m: float | None = None
    radar_height_m: float | None = None
    point_geometry: dict | None = None
    labels_vs_truth: dict | None = None


@dataclass(frozen=True)
class SidelobeShare:
    """How many points sit where angle sidelobes of stronger returns would
    (:func:`sidelobe_flags`), and the same count at a range offset as a control.

    Attributes
    ----------
    points : int — points counted (all frames).
    on_sidelobe : int — points on the range bin ± tolerance of a stronger return.
    on_control_plus, on_control_minus : int — points with a stronger return on the bins
        + offset (± tolerance) / - offset (± tolerance) instead.
    on_control_either : int — points with one on either (| |Δbin| - offset | <= tolerance):
        twice the sidelobe window's width, so it over-counts chance (kept for reference).
    share : float — ``on_sidelobe / points`` (NaN with no points).
    control_share : float — the mean of ``on_control_plus / points`` and
        ``on_control_minus / points``: each of those windows is as wide as the sidelobe
        window, so on points with no sidelobes it matches ``share`` (up to the edges of the
        range span); ``on_control_either / points`` would not (it reads higher wherever a
        window holds about one point or fewer).
    """

    points: int
    on_sidelobe: int
    on_control_plus: int
    on_control_minus: int
    on_control_either: int
    share: float
    control_share: float

    @property
    def difference(self) -> float:
        """``share - control_share``: the share above chance."""
        return self.share - self.control_share


@dataclass(frozen=True)
class DopplerStats:
    """Doppler of one dataset's points.

    Attributes
    ----------
    fraction : (B,) float64 — fraction of the points in each bin of the report's Doppler edges.
    moving_share : float — share with |Doppler| > half a bin (outside the zero bin).
    abs_median_mps : float [m/s] — median of |Doppler| (NaN with no points).
    """

    fraction: np.ndarray
    moving_share: float
    abs_median_mps: float


@dataclass(frozen=True)
class ArtefactStats:
    """Artefact figures of one dataset (:func:`artefact_stats`).

    Attributes
    ----------
    points : int — points over all frames.
    range_resolution_m : float [m] — range bin width used for the sidelobe share.
    range_resolution_from : str — ``"dataset.json"`` or :data:`DEFAULT_RESOLUTION_FROM`.
    sidelobe : :class:`SidelobeShare`.
    doppler : :class:`DopplerStats` or None — None when the points have no Doppler column.
    doppler_note : str or None — why ``doppler`` is None.
    beyond_range_share : float — share of points with range > ``far_range_m`` (NaN: no points).
    below_floor_share : float or None — share more than ``below_floor_margin_m`` below the
        floor; None when the floor height is unknown.
    radar_height_m : float or None [m] — the radar's height above the floor used.
    below_floor_note : str or None — why ``below_floor_share`` is None.
    """

    points: int
    range_resolution_m: float
    range_resolution_from: str
    sidelobe: SidelobeShare
    doppler: DopplerStats | None
    doppler_note: str | None
    beyond_range_share: float
    below_floor_share: float | None
    radar_height_m: float | None
    below_floor_note: str | None


# ------------------------------------------------------------------------- point geometry


def azimuth_deg(points: np.ndarray) -> np.ndarray:
    """Azimuth of points [deg], atan2(y, x) in [-180, 180]: 0 ahead, positive to the left.

    Parameters
    ----------
    points : (N, ≥2) float — x, y [m] in the radar frame.

    Returns
    -------
    (N,) float64 [deg]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, np.shape(points)[-1])
    return np.degrees(np.arctan2(p[:, 1], p[:, 0]))


def range_m(points: np.ndarray) -> np.ndarray:
    """Slant range of points [m], |(x, y, z)| (what the radar measures).

    Parameters
    ----------
    points : (N, ≥3) float — x, y, z [m] in the radar frame.

    Returns
    -------
    (N,) float64 [m]
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, np.shape(points)[-1])
    return np.linalg.norm(p[:, :3], axis=1)


def coverage_fractions(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Fraction of *all* ``values`` in each bin of ``edges`` (values outside every bin count in
    the total, so the fractions sum to the share inside the edges). Zeros with no values.

    Parameters
    ----------
    values : (N,) float; edges : (B + 1,) float, increasing.

    Returns
    -------
    (B,) float64
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    counts, _ = np.histogram(v, bins=np.asarray(edges, dtype=np.float64))
    return counts / v.size if v.size else np.zeros(len(edges) - 1)


def stack_points(frames: Mapping[str, np.ndarray]) -> np.ndarray:
    """All frames' points as one array: (N, 4) float32 — x, y, z [m], intensity [dB] (further
    columns dropped); (0, 4) with no frames."""
    parts = [np.asarray(p, dtype=np.float32)[:, :4] for p in frames.values()]
    return np.concatenate(parts) if parts else np.zeros((0, 4), np.float32)


# --------------------------------------------------------------------------- sidelobe share


def range_bins(points: np.ndarray, range_resolution_m: float) -> np.ndarray:
    """Range bin of each point: floor(range / range_resolution_m + 0.5), range = |(x, y, z)|
    (nearest bin centre, as :func:`sim2radar.radar.binning.bin_indices` bins returns).

    Parameters
    ----------
    points : (N, ≥3) float — x, y, z [m]; range_resolution_m : float [m].

    Returns
    -------
    (N,) int64
    """
    return np.floor(range_m(points) / range_resolution_m + 0.5).astype(np.int64)


def _window_hits(bins: np.ndarray, az_deg: np.ndarray, db: np.ndarray, lo: int, hi: int,
                 min_drop_db: float, min_sep_deg: float, max_pairs: int) -> np.ndarray:
    """(N,) bool: point i has a point j with bins[j] - bins[i] in [lo, hi], db[j] - db[i] >=
    min_drop_db and wrapped |az[j] - az[i]| > min_sep_deg.

    Pairs are enumerated on the range-sorted points, only within the window (searchsorted),
    ``max_pairs`` at a time: memory stays bounded and the work is the number of pairs in the
    window, not N²."""
    n = bins.size
    order = np.argsort(bins, kind="stable")
    b, a, d = bins[order], az_deg[order], db[order]
    first = np.searchsorted(b, b + lo, side="left")
    count = np.searchsorted(b, b + hi, side="right") - first
    hits = np.zeros(n, dtype=bool)
    ends = np.cumsum(count)
    start = 0
    while start < n:
        done = int(ends[start - 1]) if start else 0
        stop = max(start + 1, int(np.searchsorted(ends, done + max_pairs, side="right")))
        c = count[start:stop]
        total = int(c.sum())
        if total:
            i = np.repeat(np.arange(start, stop), c)
            j = first[i] + np.arange(total) - np.repeat(np.cumsum(c) - c, c)
            sep = np.abs(np.mod(a[j] - a[i] + 180.0, 360.0) - 180.0)
            ok = (d[j] - d[i] >= min_drop_db) & (sep > min_sep_deg)
            hits[start:stop] = np.bincount(i[ok] - start, minlength=stop - start) > 0
        start = stop
    out = np.empty(n, dtype=bool)
    out[order] = hits
    return out


def sidelobe_flags(points: np.ndarray, range_resolution_m: float,
                   settings: ArtefactSettings | None = None, *, max_pairs: int = 4_000_000,
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which points of one frame sit where an angle sidelobe of a stronger return would.

    Point i is *on a sidelobe bin* when another point j of the frame is at least
    ``sidelobe_min_drop_db`` stronger (intensity_j - intensity_i >= 13 dB), more than
    ``sidelobe_min_separation_deg`` away in azimuth (wrapped |atan2(y, x)| difference > 3°)
    and on its range bin ± ``sidelobe_range_tolerance_bins`` (|bin_i - bin_j| <= 1, bins of
    :func:`range_bins`). An angle sidelobe appears at its source's range and across azimuth,
    so a point-cloud that carries sidelobes as points has many; the control counts the same
    condition with the range offset by ± ``sidelobe_control_offset_bins`` (bin_j - bin_i in
    [5 - 1, 5 + 1], and in [-5 - 1, -5 + 1]), where sidelobes do not put points.

    Parameters
    ----------
    points : (N, ≥4) float — x, y, z [m] (radar frame), intensity [dB].
    range_resolution_m : float [m] — range bin width.
    settings : thresholds (defaults: :class:`ArtefactSettings`).
    max_pairs : int — candidate pairs examined at once (memory bound).

    Returns
    -------
    on_sidelobe, on_control_plus, on_control_minus : (N,) bool
    """
    s = settings or ArtefactSettings()
    if not range_resolution_m > 0:
        raise ValueError(f"range_resolution_m must be > 0, got {range_resolution_m}")
    p = np.asarray(points, dtype=np.float64).reshape(-1, np.shape(points)[-1])
    if p.shape[1] < 4:
        raise ValueError(f"points must be (N, >=4) x y z intensity, got shape {p.shape}")
    bins, az, db = range_bins(p, range_resolution_m), azimuth_deg(p), p[:, 3]
    tol, off = s.sidelobe_range_tolerance_bins, s.sidelobe_control_offset_bins
    args = (s.sidelobe_min_drop_db, s.sidelobe_min_separation_deg, max_pairs)
    return (_window_hits(bins, az, db, -tol, tol, *args),
            _window_hits(bins, az, db, off - tol, off + tol, *args),
            _window_hits(bins, az, db, -off - tol, -off + tol, *args))


def sidelobe_share(frames: Mapping[str, np.ndarray] | Sequence[np.ndarray],
                   range_resolution_m: float, settings: ArtefactSettings | None = None,
                   ) -> SidelobeShare:
    """:func:`sidelobe_flags` of every frame, counted over the dataset.

    Parameters
    ----------
    frames : {frame id: (N, ≥4) points} or a sequence of them — x, y, z [m], intensity [dB].
    range_resolution_m : float [m]; settings : thresholds (:class:`ArtefactSettings`).

    Returns
    -------
    :class:`SidelobeShare` — a dataset whose points include angle-sidelobe arcs at the range
    of strong returns has ``share`` far above ``control_share``; one without, about equal.
    """
    values = frames.values() if isinstance(frames, Mapping) else frames
    n = on = plus = minus = either = 0
    for pts in values:
        if len(pts) == 0:
            continue
        f, fp, fm = sidelobe_flags(pts, range_resolution_m, settings)
        n += f.size
        on, plus, minus = on + int(f.sum()), plus + int(fp.sum()), minus + int(fm.sum())
        either += int((fp | fm).sum())
    if n == 0:
        return SidelobeShare(0, 0, 0, 0, 0, float("nan"), float("nan"))
    return SidelobeShare(n, on, plus, minus, either, on / n, 0.5 * (plus + minus) / n)


# ---------------------------------------------------------------------------------- Doppler


def doppler_edges(doppler_mps: Sequence[np.ndarray], bin_mps: float = 0.1,
                  max_bins: int = 200) -> np.ndarray | None:
    """Doppler bin edges [m/s] over the span of all the given arrays, bins of width ``bin_mps``
    centred on multiples of it (the zero bin is [-bin/2, bin/2)), the width doubled until at
    most ``max_bins`` bins. None when no array is given; one zero bin when all are empty.

    Returns
    -------
    (D + 1,) float64 [m/s] or None
    """
    arrays = [np.asarray(v, dtype=np.float64).ravel() for v in doppler_mps]
    if not arrays:
        return None
    allv = np.concatenate(arrays)
    lo, hi = (float(allv.min()), float(allv.max())) if allv.size else (0.0, 0.0)
    step = float(bin_mps)
    while True:
        k_lo, k_hi = math.floor(lo / step + 0.5), math.floor(hi / step + 0.5)
        if k_hi - k_lo + 1 <= max_bins:
            break
        step *= 2.0
    return (np.arange(k_lo, k_hi + 2, dtype=np.float64) - 0.5) * step


def doppler_stats(doppler_mps: np.ndarray, edges_mps: np.ndarray,
                  bin_mps: float = 0.1) -> DopplerStats:
    """Histogram, moving share and |Doppler| median of one dataset's Doppler values.

    Parameters
    ----------
    doppler_mps : (N,) float [m/s] — radial velocity of each point.
    edges_mps : (D + 1,) float [m/s] — e.g. :func:`doppler_edges` of both datasets.
    bin_mps : float [m/s] — a point moves when |Doppler| > bin_mps / 2.

    Returns
    -------
    :class:`DopplerStats`
    """
    v = np.asarray(doppler_mps, dtype=np.float64).ravel()
    if v.size == 0:
        return DopplerStats(coverage_fractions(v, edges_mps), float("nan"), float("nan"))
    return DopplerStats(coverage_fractions(v, edges_mps),
                        float(np.mean(np.abs(v) > 0.5 * bin_mps)), float(np.median(np.abs(v))))


def doppler_values(frames: Mapping[str, np.ndarray]) -> tuple[np.ndarray | None, str | None]:
    """All Doppler values of a dataset (its points' 5th column), or None and why not.

    Parameters
    ----------
    frames : {frame id: (N, ≥4) float points}.

    Returns
    -------
    doppler_mps : (N,) float64 [m/s] over all frames, or None when any frame has no 5th column.
    note : str or None — why ``doppler_mps`` is None.
    """
    without = [fid for fid, p in frames.items() if np.shape(p)[1] < 5]
    if without:
        how = ("its points have no 5th column" if len(without) == len(frames)
               else f"{len(without)} of its {len(frames)} frames (e.g. {without[0]}) have no "
                    "5th column")
        return None, f"no Doppler: {how} (x y z intensity only)"
    parts = [np.asarray(p[:, 4], dtype=np.float64) for p in frames.values()]
    return (np.concatenate(parts) if parts else np.zeros(0)), None


# ------------------------------------------------------------------------------ per dataset


def artefact_stats(frames: Mapping[str, np.ndarray], info: DatasetInfo | None = None,
                   settings: ArtefactSettings | None = None,
                   doppler_edges_mps: np.ndarray | None = None, *,
                   max_bins: int = 200) -> ArtefactStats:
    """Artefact figures of one dataset: sidelobe share and control, Doppler, range beyond
    ``far_range_m`` and points below the floor (module docstring).

    Parameters
    ----------
    frames : {frame id: (N, ≥4) float points} — x, y, z [m] (radar frame), intensity [dB],
        optional Doppler [m/s] as the 5th column.
    info : what the dataset's ``dataset.json`` says (range resolution, radar height).
    settings : thresholds and defaults (:class:`ArtefactSettings`).
    doppler_edges_mps : (D + 1,) [m/s] — Doppler histogram edges (default: this dataset's
        span, :func:`doppler_edges` with at most ``max_bins`` bins).
    max_bins : int — see ``doppler_edges_mps``.

    Returns
    -------
    :class:`ArtefactStats`
    """
    s = settings or ArtefactSettings()
    info = info or DatasetInfo()
    if info.range_resolution_m is not None:
        res, res_from = float(info.range_resolution_m), "dataset.json"
    else:
        res, res_from = s.range_resolution_m, DEFAULT_RESOLUTION_FROM
    xyz = stack_points(frames)
    n = len(xyz)
    nan = float("nan")
    side = sidelobe_share(frames, res, s)
    beyond = float(np.mean(range_m(xyz) > s.far_range_m)) if n else nan

    dop, dop_note = doppler_values(frames)
    dop_stats = None
    if dop is not None:
        edges = (doppler_edges_mps if doppler_edges_mps is not None
                 else doppler_edges([dop], s.doppler_bin_mps, max_bins))
        dop_stats = doppler_stats(dop, edges, s.doppler_bin_mps)

    if info.radar_height_m is None:
        below, floor_note = None, ("floor height unknown: dataset.json has no radar_height_m "
                                   "(the radar's height above the floor [m])")
    else:
        floor_z = -float(info.radar_height_m)
        below = float(np.mean(xyz[:, 2] < floor_z - s.below_floor_margin_m)) if n else nan
        floor_note = None
    return ArtefactStats(points=n, range_resolution_m=res, range_resolution_from=res_from,
                         sidelobe=side, doppler=dop_stats, doppler_note=dop_note,
                         beyond_range_share=beyond, below_floor_share=below,
                         radar_height_m=info.radar_height_m, below_floor_note=floor_note)


def artefact_definitions(settings: ArtefactSettings | None = None) -> dict[str, str]:
    """The sentences ``gap.json`` carries to say what each artefact figure means."""
    s = settings or ArtefactSettings()
    tol, off = s.sidelobe_range_tolerance_bins, s.sidelobe_control_offset_bins
    return {
        "sidelobe": (
            f"share of a dataset's points with another point of the same frame at least "
            f"{s.sidelobe_min_drop_db:g} dB stronger, more than {s.sidelobe_min_separation_deg:g}° "
            f"away in azimuth atan2(y, x), on its range bin ±{tol} (bin = floor(range / "
            f"range_resolution_m + 0.5), range = |(x, y, z)|): where angle sidelobes of the "
            f"stronger return would be; control: the mean of the same share on the bins "
            f"+{off} ±{tol} and -{off} ±{tol} (chance); difference = share - control"),
        "doppler": (
            f"Doppler [m/s] (5th point column) in {s.doppler_bin_mps:g} m/s bins centred on 0 "
            f"over both datasets' span; moving share: |Doppler| > {s.doppler_bin_mps / 2:g} m/s; "
            "null with a note when the points have no Doppler column"),
        "beyond_range": f"share of points with range |(x, y, z)| > {s.far_range_m:g} m",
        "below_floor": (
            f"share of points more than {s.below_floor_margin_m:g} m below the floor "
            "(z < -radar_height_m - margin, radar_height_m from dataset.json); null with a note "
            "when dataset.json has no radar_height_m"),
    }


# ------------------------------------------------------------------------------------ I/O


def read_dataset_info(root: str | Path) -> DatasetInfo:
    """What ``ROOT/dataset.json`` says about the dataset's domain, range resolution and the
    radar's height above the floor (:class:`DatasetInfo`).

    No file, or no ``domain`` string in it, gives the domain ``"undeclared"``
    (:func:`sim2radar.datasets.read_metadata`: nothing is guessed "measured"). Absent (or null)
    ``range_resolution_m`` / ``radar_height_m`` give None.

    Raises
    ------
    DatasetError — the file is not a JSON object, or a key is not a finite number
    (``range_resolution_m`` > 0, ``radar_height_m`` >= 0); the file and key are named.
    """
    path = Path(root) / METADATA_FILE
    doc = read_metadata(root)
    domain = doc.get("domain")
    values: dict[str, float | None] = {}
    for key, low, strict in (("range_resolution_m", 0.0, True), ("radar_height_m", 0.0, False)):
        v = doc.get(key)
        if v is None:
            values[key] = None
            continue
        ok = (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
              and (v > low if strict else v >= low))
        if not ok:
            raise DatasetError(f"{path}: {key} must be a number {'>' if strict else '>='} "
                               f"{low:g} [m], got {v!r}; fix it or remove the key")
        values[key] = float(v)
    measured = {}
    for key in ("point_geometry", "labels_vs_truth"):
        v = doc.get(key)
        if v is not None and not isinstance(v, dict):
            raise DatasetError(f"{path}: {key} must be an object (or null), got "
                               f"{type(v).__name__}; fix it or remove the key")
        measured[key] = v
    return DatasetInfo(domain=domain if isinstance(domain, str) and domain.strip()
                       else UNDECLARED, **values, **measured)
