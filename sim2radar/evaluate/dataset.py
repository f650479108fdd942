"""Figures of a generated radar dataset, per geometry: points and labels per frame, label
recall / precision against the ground-truth doors in the radar's view, sim-vs-GT comparison of
one frame (points ratio, radar Chamfer distance), seconds per stage. :func:`frame_measures`
measures one frame; the others pool the factory's per-frame outcome records (anything with
``measured`` holding those measures and ``timings_s``, :class:`sim2radar.tasks.common.Outcome`),
so the figures of a run come from its records without reading a frame back."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

__all__ = ["LABEL_IOU_THRESHOLD", "finite_mean", "frame_measures", "match_ratio",
           "geometry_metrics", "stage_seconds", "compare_frames"]

#: 3D IoU at which a label counts as matching a ground-truth door (the paper's AP threshold).
LABEL_IOU_THRESHOLD = 0.3


def finite_mean(values: Iterable) -> float:
    """Mean of the finite values (None, NaN and inf left out); NaN when there are none."""
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return float(np.mean(v)) if v else float("nan")


def frame_measures(df, iou_threshold: float = LABEL_IOU_THRESHOLD) -> dict:
    """What one dataset frame (:class:`sim2radar.factory.frames.DatasetFrame`) of geometry
    ``g`` measures: ``n_points`` {g: radar points}, ``n_labels`` {g: labelled boxes},
    ``n_gt_doors`` (ground-truth doors the radar sees), ``gt_points_near`` {g: radar points
    near each of them}, ``label_match`` {g: ``tp``, ``n_pred``, ``n_gt``: labels matched
    one-to-one to those doors at 3D IoU >= ``iou_threshold``}, ``label_points`` {g: points
    inside each label box}, ``label_size_error`` {g: per matched label ``[d_width, d_depth,
    d_height, centre distance]`` [m]} and ``point_geometry`` {g: ``points``, ``behind`` (more
    than 1 m behind the world's first surface, when the frame knows it) and ``beyond``
    (beyond 0.85 R_max, when its radar stats give R_max)}
    (:mod:`sim2radar.evaluate.fidelity`)."""
    from sim2radar.evaluate.fidelity import (
        BEHIND_SURFACE_M,
        FAR_RANGE_FRACTION,
        box_size_errors,
        points_per_box,
    )
    from sim2radar.evaluate.reconstruction import match_boxes

    g = df.geometry
    m = match_boxes(df.boxes, df.gt_boxes, iou_threshold)
    points = np.asarray(df.points, np.float64).reshape(-1, 4)
    geo: dict[str, int] = {"points": int(len(points))}
    if df.surface_offset_m is not None:
        geo["behind"] = int(np.count_nonzero(np.asarray(df.surface_offset_m) > BEHIND_SURFACE_M))
    max_range = (df.stats.get("radar") or {}).get("max_range_m")
    if max_range:
        rng = np.linalg.norm(points[:, :3], axis=1)
        geo["beyond"] = int(np.count_nonzero(rng > FAR_RANGE_FRACTION * float(max_range)))
    errors = box_size_errors(df.boxes, df.gt_boxes, m["pairs"])
    return {"n_points": {g: int(len(df.points))}, "n_labels": {g: int(len(df.boxes))},
            "n_gt_doors": int(len(df.gt_boxes)),
            "gt_points_near": {g: [int(v) for v in df.gt_points_near]},
            "label_match": {g: {"tp": int(m["tp"]), "n_pred": int(m["n_pred"]),
                                "n_gt": int(m["n_gt"])}},
            "label_points": {g: [int(v) for v in points_per_box(points, df.boxes)]},
            "label_size_error": {g: [[round(float(v), 4) for v in row] for row in errors]},
            "point_geometry": {g: geo}}


def _measure(frame, name: str, default):
    return frame.measured.get(name, default)


def match_ratio(frames: Sequence, geometry: str, denominator: str) -> float:
    """Matched labels (``tp``) over ``n_gt`` (recall) or ``n_pred`` (precision), pooled over
    frames; NaN when the denominator is 0 (e.g. no ground truth)."""
    matches = [_measure(f, "label_match", {}).get(geometry, {}) for f in frames]
    tp = sum(m.get("tp", 0) for m in matches)
    n = sum(m.get(denominator, 0) for m in matches)
    return tp / n if n else float("nan")


def _pooled_share(frames: Sequence, geometry: str, part: str) -> float:
    """``point_geometry[part]`` over its ``points``, pooled over the frames that measured it."""
    geo = [_measure(f, "point_geometry", {}).get(geometry, {}) for f in frames]
    geo = [x for x in geo if part in x]
    n = sum(x["points"] for x in geo)
    return sum(x[part] for x in geo) / n if n else float("nan")


def geometry_metrics(frames: Sequence, geometries: Sequence[str]) -> dict[str, dict]:
    """Per geometry: ``frames``, ``points_per_frame``, ``labels_per_frame``,
    ``gt_doors_per_frame``, ``frac_frames_with_label``, ``frac_gt_doors_with_points``,
    ``label_recall`` / ``label_precision`` (3D IoU >= :data:`LABEL_IOU_THRESHOLD`),
    ``behind_surface_share`` / ``beyond_range_share`` (pooled points more than 1 m behind the
    world's first surface / beyond 0.85 R_max), ``points_per_label`` (median points inside a
    label box), ``labels_without_points`` (their share with none) and the mean absolute size
    errors of matched labels ``label_width_error_m``, ``label_depth_error_m``,
    ``label_height_error_m`` and their mean ``label_centre_error_m``."""
    out = {}
    for g in geometries:
        done = [f for f in frames if g in _measure(f, "n_points", {})]
        near = [n for f in done for n in _measure(f, "gt_points_near", {}).get(g, [])]
        labels = [f.measured["n_labels"][g] for f in done]
        inside = [n for f in done for n in _measure(f, "label_points", {}).get(g, [])]
        err = np.array([e for f in done for e in _measure(f, "label_size_error", {}).get(g, [])],
                       np.float64).reshape(-1, 4)
        mean_abs = (np.abs(err).mean(axis=0) if len(err) else np.full(4, np.nan))
        out[g] = {
            "frames": len(done),
            "points_per_frame": finite_mean(f.measured["n_points"][g] for f in done),
            "labels_per_frame": finite_mean(labels),
            "gt_doors_per_frame": finite_mean(_measure(f, "n_gt_doors", 0) for f in done),
            "frac_frames_with_label": finite_mean(n > 0 for n in labels),
            "frac_gt_doors_with_points": finite_mean(n > 0 for n in near),
            "label_recall": match_ratio(done, g, "n_gt"),
            "label_precision": match_ratio(done, g, "n_pred"),
            "behind_surface_share": _pooled_share(done, g, "behind"),
            "beyond_range_share": _pooled_share(done, g, "beyond"),
            "points_per_label": float(np.median(inside)) if inside else float("nan"),
            "labels_without_points": finite_mean(n == 0 for n in inside),
            "label_width_error_m": float(mean_abs[0]),
            "label_depth_error_m": float(mean_abs[1]),
            "label_height_error_m": float(mean_abs[2]),
            "label_centre_error_m": float(mean_abs[3]),
        }
    return out


def stage_seconds(frames: Sequence) -> dict[str, float]:
    """Mean seconds per frame of every stage found in the frames' ``timings_s``."""
    stages = sorted({s for f in frames for s in f.timings_s})
    return {s: finite_mean(f.timings_s[s] for f in frames if s in f.timings_s) for s in stages}


def compare_frames(gt_points: np.ndarray, rec_points: np.ndarray) -> dict[str, float]:
    """Sim-vs-GT figures of one frame: points ratio (reconstructed / ground truth) and the
    symmetric Chamfer distance [m] between the two radar point clouds."""
    from sim2radar.evaluate.reconstruction import chamfer_distance

    n_gt, n_rec = len(gt_points), len(rec_points)
    return {
        "points_ratio": float(n_rec / n_gt) if n_gt else float("nan"),
        "chamfer_m": chamfer_distance(rec_points, gt_points),
    }
