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
    one-to-one to those doors at 3D IoU >= ``iou_threshold``}."""
    from sim2radar.evaluate.reconstruction import match_boxes

    g = df.geometry
    m = match_boxes(df.boxes, df.gt_boxes, iou_threshold)
    return {"n_points": {g: int(len(df.points))}, "n_labels": {g: int(len(df.boxes))},
            "n_gt_doors": int(len(df.gt_boxes)),
            "gt_points_near": {g: [int(v) for v in df.gt_points_near]},
            "label_match": {g: {"tp": int(m["tp"]), "n_pred": int(m["n_pred"]),
                                "n_gt": int(m["n_gt"])}}}


def _measure(frame, name: str, default):
    return frame.measured.get(name, default)


def match_ratio(frames: Sequence, geometry: str, denominator: str) -> float:
    """Matched labels (``tp``) over ``n_gt`` (recall) or ``n_pred`` (precision), pooled over
    frames; NaN when the denominator is 0 (e.g. no ground truth)."""
    matches = [_measure(f, "label_match", {}).get(geometry, {}) for f in frames]
    tp = sum(m.get("tp", 0) for m in matches)
    n = sum(m.get(denominator, 0) for m in matches)
    return tp / n if n else float("nan")


def geometry_metrics(frames: Sequence, geometries: Sequence[str]) -> dict[str, dict]:
    """Per geometry: ``frames``, ``points_per_frame``, ``labels_per_frame``,
    ``gt_doors_per_frame``, ``frac_frames_with_label``, ``frac_gt_doors_with_points``,
    ``label_recall`` / ``label_precision`` (3D IoU >= :data:`LABEL_IOU_THRESHOLD`)."""
    out = {}
    for g in geometries:
        done = [f for f in frames if g in _measure(f, "n_points", {})]
        near = [n for f in done for n in _measure(f, "gt_points_near", {}).get(g, [])]
        labels = [f.measured["n_labels"][g] for f in done]
        out[g] = {
            "frames": len(done),
            "points_per_frame": finite_mean(f.measured["n_points"][g] for f in done),
            "labels_per_frame": finite_mean(labels),
            "gt_doors_per_frame": finite_mean(_measure(f, "n_gt_doors", 0) for f in done),
            "frac_frames_with_label": finite_mean(n > 0 for n in labels),
            "frac_gt_doors_with_points": finite_mean(n > 0 for n in near),
            "label_recall": match_ratio(done, g, "n_gt"),
            "label_precision": match_ratio(done, g, "n_pred"),
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
