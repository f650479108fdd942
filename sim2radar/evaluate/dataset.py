"""Figures of a generated radar dataset, per geometry: points and labels per frame, label
recall / precision against the ground-truth doors in the radar's view, sim-vs-GT comparison of
one frame (points ratio, radar Chamfer distance), seconds per stage. Inputs are the factory's
per-frame outcome records (:class:`sim2radar.tasks.dataset.FrameOutcome`: ``n_points``, ``n_labels``,
``n_gt_doors``, ``gt_points_near``, ``label_match``, ``timings_s``), so the figures of a run
come from its records without reading a frame back."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

import numpy as np

__all__ = ["LABEL_IOU_THRESHOLD", "finite_mean", "match_ratio", "geometry_metrics",
           "stage_seconds", "compare_frames"]

#: 3D IoU at which a label counts as matching a ground-truth door (the paper's AP threshold).
LABEL_IOU_THRESHOLD = 0.3


def finite_mean(values: Iterable) -> float:
    """Mean of the finite values (None, NaN and inf left out); NaN when there are none."""
    v = [float(x) for x in values if x is not None and math.isfinite(float(x))]
    return float(np.mean(v)) if v else float("nan")


def match_ratio(frames: Sequence, geometry: str, denominator: str) -> float:
    """Matched labels (``tp``) over ``n_gt`` (recall) or ``n_pred`` (precision), pooled over
    frames; NaN when the denominator is 0 (e.g. no ground truth)."""
    tp = sum(f.label_match.get(geometry, {}).get("tp", 0) for f in frames)
    n = sum(f.label_match.get(geometry, {}).get(denominator, 0) for f in frames)
    return tp / n if n else float("nan")


def geometry_metrics(frames: Sequence, geometries: Sequence[str]) -> dict[str, dict]:
    """Per geometry: ``frames``, ``points_per_frame``, ``labels_per_frame``,
    ``gt_doors_per_frame``, ``frac_frames_with_label``, ``frac_gt_doors_with_points``,
    ``label_recall`` / ``label_precision`` (3D IoU >= :data:`LABEL_IOU_THRESHOLD`)."""
    out = {}
    for g in geometries:
        done = [f for f in frames if g in f.n_points]
        near = [n for f in done for n in f.gt_points_near.get(g, [])]
        out[g] = {
            "frames": len(done),
            "points_per_frame": finite_mean(f.n_points[g] for f in done),
            "labels_per_frame": finite_mean(f.n_labels[g] for f in done),
            "gt_doors_per_frame": finite_mean(f.n_gt_doors for f in done),
            "frac_frames_with_label": finite_mean(f.n_labels[g] > 0 for f in done),
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
