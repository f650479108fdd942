"""Training-time augmentation (OpenPCDet ``DataAugmentor`` / ``DataBaseSampler``), NumPy.

Order as in OpenPCDet's KITTI PointPillars config: ground-truth sampling, random flip along x,
global rotation about z, global scaling; then boxes with no corner inside the point-cloud range
are dropped and the points shuffled. Every function takes an explicit ``numpy.random.Generator``
so a (seed, epoch) pair reproduces an epoch exactly.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from sim2radar.boxes import box_corners, points_in_boxes
from sim2radar.datasets.openpcdet import Frame
from sim2radar.detect.config import AugmentConfig
from sim2radar.evaluate.iou import bev_overlaps

__all__ = [
    "GTDatabase",
    "augment_frame",
    "box_corners_3d",
    "boxes_in_range",
    "build_gt_database",
    "global_rotation",
    "global_scaling",
    "points_in_boxes",
    "random_flip_x",
    "sample_ground_truth",
]


box_corners_3d = box_corners  # OpenPCDet's name


def boxes_in_range(boxes: np.ndarray, point_cloud_range_m: Sequence[float]) -> np.ndarray:
    """(M,) mask: at least one corner inside the range (OpenPCDet ``mask_boxes_outside_range``)."""
    if len(boxes) == 0:
        return np.zeros(0, dtype=bool)
    r = np.asarray(point_cloud_range_m)
    corners = box_corners_3d(boxes)
    inside = ((corners >= r[:3]) & (corners <= r[3:])).all(axis=2)
    return inside.any(axis=1)


@dataclass
class GTDatabase:
    """Ground-truth boxes of the training split with the points inside them."""

    boxes: dict[str, list[np.ndarray]] = field(default_factory=dict)
    points: dict[str, list[np.ndarray]] = field(default_factory=dict)

    def __len__(self) -> int:
        return sum(len(v) for v in self.boxes.values())


def build_gt_database(
    frames: Sequence[Frame], class_names: Sequence[str], min_points: int = 5
) -> GTDatabase:
    """Collect every box of ``class_names`` with >= ``min_points`` points (train split only).

    Entries keep their original pose: pasting a sampled door puts it where it was recorded,
    as OpenPCDet does.
    """
    db = GTDatabase()
    for f in frames:
        inside = points_in_boxes(f.points, f.boxes)
        for m, name in enumerate(f.names):
            if name not in class_names:
                continue
            pts = f.points[inside[:, m]]
            if len(pts) < min_points:
                continue
            db.boxes.setdefault(name, []).append(f.boxes[m].astype(np.float32))
            db.points.setdefault(name, []).append(pts)
    return db


def sample_ground_truth(
    points: np.ndarray,
    boxes: np.ndarray,
    names: tuple[str, ...],
    db: GTDatabase,
    sample_groups: dict[str, int],
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Paste database objects into a frame up to ``sample_groups[class]`` boxes per class.

    Candidates that overlap (rotated BEV IoU > 0) an existing box or another candidate are
    rejected; the frame's points inside accepted boxes are replaced by the object's points.
    """
    out_pts, out_boxes, out_names = [points], [boxes.reshape(-1, 7)], list(names)
    for name, target in sample_groups.items():
        pool = db.boxes.get(name, [])
        n = target - sum(1 for x in names if x == name)
        if n <= 0 or not pool:
            continue
        pick = rng.choice(len(pool), size=min(n, len(pool)), replace=False)
        cand = np.stack([pool[i] for i in pick]).astype(np.float64)
        existing = np.concatenate(out_boxes).astype(np.float64)
        # IoU > 0 with another candidate or a box already there (one call: its fixed cost once)
        overlap = bev_overlaps(cand, np.concatenate([cand, existing]))
        np.fill_diagonal(overlap[:, :len(cand)], False)
        ok = np.flatnonzero(~overlap.any(axis=1))
        if ok.size == 0:
            continue
        new_boxes = cand[ok].astype(np.float32)
        inside = points_in_boxes(out_pts[0], new_boxes).any(axis=1)
        out_pts[0] = out_pts[0][~inside]
        out_pts += [db.points[name][pick[i]] for i in ok]
        out_boxes.append(new_boxes)
        out_names += [name] * len(ok)
    return np.concatenate(out_pts), np.concatenate(out_boxes), tuple(out_names)


def random_flip_x(points, boxes, rng):
    """With probability 1/2 mirror across the x axis: y -> -y, heading -> -heading."""
    if rng.random() < 0.5:
        points = points.copy()
        boxes = boxes.copy()
        points[:, 1] = -points[:, 1]
        boxes[:, 1] = -boxes[:, 1]
        boxes[:, 6] = -boxes[:, 6]
    return points, boxes


def global_rotation(points, boxes, rot_range, rng):
    """Rotate the scene about z by an angle uniform in ``rot_range`` [rad]."""
    a = rng.uniform(*rot_range)
    c, s = np.cos(a), np.sin(a)
    points = points.copy()
    boxes = boxes.copy()
    x, y = points[:, 0].copy(), points[:, 1].copy()
    points[:, 0], points[:, 1] = x * c - y * s, x * s + y * c
    bx, by = boxes[:, 0].copy(), boxes[:, 1].copy()
    boxes[:, 0], boxes[:, 1] = bx * c - by * s, bx * s + by * c
    boxes[:, 6] += a
    return points, boxes


def global_scaling(points, boxes, scale_range, rng):
    """Scale xyz and box centres/sizes by a factor uniform in ``scale_range``."""
    f = rng.uniform(*scale_range)
    points = points.copy()
    boxes = boxes.copy()
    points[:, :3] *= f
    boxes[:, :6] *= f
    return points, boxes


def augment_frame(
    frame: Frame,
    cfg: AugmentConfig,
    rng: np.random.Generator,
    point_cloud_range_m: Sequence[float],
    db: GTDatabase | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Apply the training augmentations to one frame; returns points, boxes, names."""
    pts, boxes, names = frame.points, frame.boxes.reshape(-1, 7), frame.names
    if cfg.gt_sampling and db is not None and len(db):
        pts, boxes, names = sample_ground_truth(pts, boxes, names, db, cfg.sample_groups, rng)
    if cfg.random_flip_x:
        pts, boxes = random_flip_x(pts, boxes, rng)
    pts, boxes = global_rotation(pts, boxes, cfg.rotation_range_rad, rng)
    pts, boxes = global_scaling(pts, boxes, cfg.scale_range, rng)
    keep = boxes_in_range(boxes, point_cloud_range_m)
    boxes = boxes[keep]
    names = tuple(n for n, k in zip(names, keep, strict=True) if k)
    if cfg.shuffle_points:
        pts = pts[rng.permutation(len(pts))]
    return pts.astype(np.float32), boxes.astype(np.float32), names
