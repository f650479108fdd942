"""The sim–real gap report of radar point clouds (paper §4.3, Figure 3, §7.3).

Compares a simulated radar dataset (SIM) with a reference one (REAL: measured radar, or the
project's labelled proxy for it) on what the paper reports: points per frame and their ratio
(the paper's is 12 %: 251 vs 2,057), azimuth and range coverage, an effective azimuth field of
view (the paper's is ~31° simulated vs the radar's 120°), intensity distributions before and
after log-space histogram matching (:mod:`sim2radar.radar.intensity`), and the Chamfer distance
between frames that show the same world from the same pose (a shared frame id).

The report is in three modules; every public name of the other two is re-exported here:

- :mod:`sim2radar.evaluate.gap_metrics` — :class:`GapSettings`, the result types and the pure
  measures (:func:`compute_gap`, :func:`effective_fov` and the definition of the effective
  azimuth field of view, :func:`chamfer_pairs`, :func:`histogram_edges`).
- :mod:`sim2radar.evaluate.gap_figures` — the PNGs (:func:`overlay_png`, :func:`gap_figures`,
  :data:`FIGURES`).
- this module — :func:`write_gap_report`, which reads the two dataset folders it is given, and
  writes ``gap.json`` (:func:`artefacts_dict` is its artefacts section, :func:`overlay_dict`
  the overlay's points: with the per-frame point counts, every figure's numbers are in it, so
  the dashboard draws them itself) and the PNGs into the folder it is given.

Coordinates are the radar frame: x forward, y left, z up [m]; intensities [dB].

Artefact figures
    Per dataset: the sidelobe share against its control, Doppler, the share beyond 8 m, the
    share below the floor, and the domain its ``dataset.json`` declares. They are defined,
    measured and given their thresholds (:class:`~sim2radar.evaluate.artefacts.ArtefactSettings`,
    held as ``GapSettings.artefacts``) in :mod:`sim2radar.evaluate.artefacts`; this module puts
    both datasets' figures in ``gap.json["artefacts"]`` (:func:`artefacts_dict`) and
    :mod:`sim2radar.evaluate.gap_figures` draws ``artefacts.png``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from sim2radar.datasets.openpcdet import DatasetError, read_labels, read_points
from sim2radar.evaluate.artefacts import DatasetInfo, artefact_definitions, read_dataset_info
from sim2radar.evaluate.fidelity import (
    BEHIND_SURFACE_M,
    FAR_RANGE_FRACTION,
    domain_fidelity,
    fidelity_readings,
)
from sim2radar.evaluate.gap_figures import FIGURES, _pct, fidelity_png, gap_figures, overlay_png
from sim2radar.evaluate.gap_metrics import (
    ChamferResult,
    FovInterval,
    GapReport,
    GapSettings,
    PointCountStats,
    chamfer_pairs,
    compute_gap,
    effective_fov,
    fov_definition,
    histogram_edges,
    point_count_stats,
)
from sim2radar.fileio import atomic_write, jsonable, write_json
from sim2radar.radar.intensity import fit_intensity_match

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
    "overlay_dict",
    "overlay_png",
    "point_count_stats",
    "write_gap_report",
]


#: What each figure of ``gap.json["fidelity"]`` measures.
FIDELITY_DEFINITIONS = {
    "behind_share": f"share of points more than {BEHIND_SURFACE_M:g} m behind the first "
                    "surface of the true geometry along their ray from the radar (multipath, "
                    "returns through slabs); from the dataset's dataset.json point_geometry, "
                    "written by the factory for procedural worlds",
    "beyond_share": f"share of points beyond {FAR_RANGE_FRACTION:g} R_max (the device's chain "
                    "tests range bins up to ~0.87 R_max; its IF filter rolls off from 0.9)",
    "points_per_label": "median number of points inside a door label box (no margin)",
    "labels_empty": "share of door label boxes with no point inside",
    "azimuth": "1 % and 99 % percentiles of the points' azimuth atan2(y, x)",
    "labels_vs_truth": "the dataset's door labels against the true doors the radar sees, "
                       "one-to-one at 3D IoU 0.3; width/depth error of the matched labels",
}


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
    ``intensity.png``, ``points.png``, ``artefacts.png``, ``fidelity.png`` (where the points
    are against the true geometry and what the door labels hold,
    :mod:`sim2radar.evaluate.fidelity`).

    Parameters
    ----------
    sim_root, real_root : dataset folders (SIM: simulated; REAL: measured or the reference
        radar's proxy). Frames are the ``points/*.npy`` files, sorted by id; labels are read
        for the overlay frame (drawn when present) and the door figures.
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
         "overlay": {"frame", "sim_frame", "real_frame", "title", "sim_points",
                     "real_points", "boxes"} (:func:`overlay_dict`: the overlay's points),
         "points": {"sim_counts", "real_counts"} (points in each analysed frame),
         "artefacts": {"settings", "definitions", "doppler_edges_mps", "sim", "real"}
                      (:func:`artefacts_dict`),
         "fidelity": {"sim", "real" (:class:`~sim2radar.evaluate.fidelity.DomainFidelity`),
                      "readings" (one sentence per figure), "definitions"},
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
    overlay = overlay_dict(sim_pts, real_pts, boxes, title=title, frame=chosen,
                           sim_frame=chosen or sim_ids[0], real_frame=chosen or real_ids[0])
    for name, data in gap_figures(rep).items():
        atomic_write(out_dir / FIGURES[name], data)
    fid = {role: domain_fidelity(pts, _labels(root, pts), info.point_geometry,
                                 info.labels_vs_truth)
           for role, pts, root, info in (("sim", sim, sim_root, rep.info_sim),
                                         ("real", real, real_root, rep.info_real))}
    atomic_write(out_dir / FIGURES["fidelity"],
                 fidelity_png(fid["sim"], fid["real"], rep.info_sim.domain, rep.info_real.domain))

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
        "overlay": overlay,
        "points": {"sim_counts": rep.sim.counts, "real_counts": rep.real.counts},
        "artefacts": artefacts_dict(rep),
        "fidelity": {"sim": fid["sim"].to_dict(), "real": fid["real"].to_dict(),
                     "readings": fidelity_readings(fid["sim"], fid["real"]),
                     "definitions": FIDELITY_DEFINITIONS},
        "figures": dict(FIGURES),
    })
    write_json(out_dir / "gap.json", doc)
    return doc


#: decimals of the overlay's coordinates in ``gap.json`` [m]: 1 mm, far below a range bin
OVERLAY_DECIMALS_M = 3
#: decimals of the overlay's intensities in ``gap.json`` [dB]
OVERLAY_DECIMALS_DB = 1


def overlay_dict(sim_points: np.ndarray, real_points: np.ndarray, boxes: np.ndarray | None,
                 *, title: str, frame: str | None, sim_frame: str, real_frame: str,
                 ) -> dict[str, Any]:
    """``gap.json["overlay"]``: the overlay figure's numbers, so a viewer can draw it
    (the dashboard's interactive overlay) without the datasets.

    Parameters
    ----------
    sim_points, real_points : (N, ≥4), (M, ≥4) — x, y, z [m], intensity [dB] of the frames
        drawn.
    boxes : (K, 7) or None — ``x y z dx dy dz heading`` [m, rad] labels drawn.
    title : the PNG's title; frame : the shared frame id (None: different scenes);
    sim_frame, real_frame : the frame ids drawn.

    Returns
    -------
    dict — ``frame``, ``sim_frame``, ``real_frame``, ``title``, ``sim_points`` and
    ``real_points`` ((N, 4) lists: x, y, z rounded to :data:`OVERLAY_DECIMALS_M`, intensity
    to :data:`OVERLAY_DECIMALS_DB`), ``boxes`` ((K, 7) list).
    """
    def rounded(p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, np.float64).reshape(-1, np.shape(p)[-1])[:, :4]
        return np.concatenate([np.round(p[:, :3], OVERLAY_DECIMALS_M),
                               np.round(p[:, 3:4], OVERLAY_DECIMALS_DB)], axis=1)

    bxs = np.zeros((0, 7)) if boxes is None else np.asarray(boxes, np.float64).reshape(-1, 7)
    return {"frame": frame, "sim_frame": sim_frame, "real_frame": real_frame, "title": title,
            "sim_points": rounded(sim_points), "real_points": rounded(real_points),
            "boxes": bxs}


def _labels(root: Path, frames: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The label boxes of the analysed frames that have a label file."""
    out = {}
    for fid in frames:
        path = root / "labels" / f"{fid}.txt"
        if path.is_file():
            out[fid] = np.asarray(read_labels(path)[0], np.float64).reshape(-1, 7)
    return out


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
