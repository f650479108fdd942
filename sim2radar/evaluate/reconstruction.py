"""Scores of a reconstruction against procedural-world ground truth (issue 5).

Depth: AbsRel = mean |d − d*| / d* and δ<1.25 = fraction of pixels with max(d/d*, d*/d) < 1.25
(Eigen et al., NeurIPS 2014, §4), over pixels valid in both maps, plus coverage.
Segmentation: per-class IoU = TP / (TP + FP + FN) accumulated over frames; mIoU over the classes
present in the ground truth. Materials: pixel-weighted accuracy over ground-truth-labelled
pixels, and per-class accuracy (recall). Doors: 3D IoU of ``x y z dx dy dz heading`` boxes
(rotated bird's-eye-view overlap × height overlap), greedy one-to-one matching by IoU, recall
and precision at an IoU threshold. Radar: symmetric Chamfer distance between point clouds
simulated on reconstructed and on ground-truth geometry, and their points-per-frame ratio.

All functions are pure NumPy (shapely for polygon overlap, scipy for nearest neighbours).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim2radar.vocab import MATERIAL_CLASSES, SEMANTIC_CLASSES

__all__ = [
    "depth_metrics",
    "SegmentationCounts",
    "segmentation_counts",
    "MaterialCounts",
    "material_counts",
    "box_iou_3d",
    "match_boxes",
    "chamfer_distance",
    "doorway_visible_fraction",
    "ReconstructionScores",
    "score_reconstruction",
    "aggregate_scores",
]


def depth_metrics(pred_m: np.ndarray, gt_m: np.ndarray) -> dict[str, float]:
    """AbsRel, δ<1.25 and coverage of a depth map.

    Parameters
    ----------
    pred_m, gt_m : (H, W) float — z-depth [m]; 0/NaN where invalid.

    Returns
    -------
    dict with ``abs_rel``, ``delta_1_25`` (over pixels valid in both), ``coverage`` (fraction
    of valid ground-truth pixels that have a prediction) and ``n_px``.
    """
    p = np.asarray(pred_m, np.float64)
    g = np.asarray(gt_m, np.float64)
    if p.shape != g.shape:
        raise ValueError(f"depth maps differ in shape: {p.shape} vs {g.shape}")
    gv = np.isfinite(g) & (g > 0)
    both = gv & np.isfinite(p) & (p > 0)
    if not both.any():
        return {"abs_rel": float("nan"), "delta_1_25": float("nan"), "coverage": 0.0, "n_px": 0}
    ratio = p[both] / g[both]
    return {
        "abs_rel": float(np.mean(np.abs(ratio - 1))),
        "delta_1_25": float(np.mean(np.maximum(ratio, 1 / ratio) < 1.25)),
        "coverage": float(both.sum() / max(gv.sum(), 1)),
        "n_px": int(both.sum()),
    }


@dataclasses.dataclass
class SegmentationCounts:
    """Per-class intersection and union pixel counts (index = ``vocab.SEMANTIC_CLASSES``)."""

    intersection: np.ndarray
    union: np.ndarray
    gt_pixels: np.ndarray

    def __add__(self, other: SegmentationCounts) -> SegmentationCounts:
        return SegmentationCounts(self.intersection + other.intersection,
                                  self.union + other.union, self.gt_pixels + other.gt_pixels)

    def iou(self) -> dict[str, float]:
        """IoU per class present in the ground truth."""
        return {SEMANTIC_CLASSES[c]: float(self.intersection[c] / self.union[c])
                for c in range(1, len(SEMANTIC_CLASSES)) if self.gt_pixels[c] > 0}

    def miou(self) -> float:
        v = list(self.iou().values())
        return float(np.mean(v)) if v else float("nan")


def segmentation_counts(pred_sem: np.ndarray, gt_sem: np.ndarray) -> SegmentationCounts:
    """Counts over pixels where the ground truth has a surface (gt > 0); a prediction of 0
    (unknown) there counts as a miss."""
    p = np.asarray(pred_sem).astype(np.int64).ravel()
    g = np.asarray(gt_sem).astype(np.int64).ravel()
    keep = g > 0
    p, g = p[keep], g[keep]
    n = len(SEMANTIC_CLASSES)
    inter = np.bincount(g[p == g], minlength=n)[:n]
    gt_px = np.bincount(g, minlength=n)[:n]
    pred_px = np.bincount(p, minlength=n)[:n]
    return SegmentationCounts(inter, gt_px + pred_px - inter, gt_px)


@dataclasses.dataclass
class MaterialCounts:
    """Correct / total pixels per ground-truth material (index = ``vocab.MATERIAL_CLASSES``)."""

    correct: np.ndarray
    total: np.ndarray

    def __add__(self, other: MaterialCounts) -> MaterialCounts:
        return MaterialCounts(self.correct + other.correct, self.total + other.total)

    def accuracy(self) -> float:
        """Pixel-weighted accuracy."""
        t = self.total.sum()
        return float(self.correct.sum() / t) if t else float("nan")

    def per_class(self) -> dict[str, float]:
        return {MATERIAL_CLASSES[c]: float(self.correct[c] / self.total[c])
                for c in range(1, len(MATERIAL_CLASSES)) if self.total[c] > 0}


def material_counts(pred_mat: np.ndarray, gt_mat: np.ndarray) -> MaterialCounts:
    """Counts over pixels with a ground-truth material (gt > 0)."""
    p = np.asarray(pred_mat).astype(np.int64).ravel()
    g = np.asarray(gt_mat).astype(np.int64).ravel()
    keep = g > 0
    p, g = p[keep], g[keep]
    n = len(MATERIAL_CLASSES)
    return MaterialCounts(np.bincount(g[p == g], minlength=n)[:n], np.bincount(g, minlength=n)[:n])


def box_iou_3d(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, M) float64 3D IoU of rotated boxes ``x y z dx dy dz heading`` (rotation about z;
    z the box centre) — the detector's KITTI-protocol IoU, :func:`sim2radar.evaluate.iou.iou_3d`."""
    a = np.asarray(a, np.float64).reshape(-1, 7)
    b = np.asarray(b, np.float64).reshape(-1, 7)
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    from sim2radar.evaluate.iou import iou_3d  # torch: imported only when boxes are compared

    return np.asarray(iou_3d(a, b), dtype=np.float64)


def match_boxes(pred: np.ndarray, gt: np.ndarray, iou_threshold: float = 0.3,
                ignore: np.ndarray | None = None) -> dict:
    """Greedy one-to-one matching by descending IoU.

    Parameters
    ----------
    pred : (N, 7), gt : (M, 7) — boxes ``x y z dx dy dz heading``.
    iou_threshold : float — a match counts at IoU ≥ this.
    ignore : (K, 7), optional — "don't care" ground truth (e.g. doors too little seen to be
        required, KITTI's DontCare): a prediction not matched to ``gt`` at ≥ the threshold that
        overlaps one of these at ≥ the threshold is neither a true nor a false positive (it is
        dropped from ``n_pred``).

    Returns
    -------
    dict: ``tp`` (matched pairs at ≥ threshold), ``n_pred``, ``n_gt``, ``recall``,
    ``precision``, ``ious`` (best IoU of each ground-truth box, 0 if unmatched),
    ``n_ignored`` (predictions dropped by ``ignore``), ``pairs`` (the matched ``(pred index,
    gt index)`` pairs at ≥ threshold).
    """
    pred = np.asarray(pred, np.float64).reshape(-1, 7)
    gt_arr = np.asarray(gt, np.float64).reshape(-1, 7)
    if (ignore is None and pred.shape == gt_arr.shape and np.array_equal(pred, gt_arr)
            and (pred[:, 3:6] > 0).all()):
        # the labels are the ground truth (the ground-truth geometry): each box matches itself
        # at IoU 1, the best any pair can reach, so the greedy matching pairs them one-to-one
        n = len(pred)
        return {"tp": n, "n_pred": n, "n_gt": n, "recall": 1.0 if n else float("nan"),
                "precision": 1.0 if n else float("nan"), "ious": np.ones(n), "n_ignored": 0,
                "pairs": [(i, i) for i in range(n)]}
    iou = box_iou_3d(pred, gt)
    n_pred, n_gt = iou.shape
    best = np.zeros(n_gt)
    hit = np.zeros(n_pred, bool)
    used_p, used_g = set(), set()
    pairs: list[tuple[int, int]] = []
    order = np.dstack(np.unravel_index(np.argsort(-iou, axis=None), iou.shape))[0] if iou.size else []
    for i, j in order:
        if iou[i, j] <= 0:
            break
        if i in used_p or j in used_g:
            continue
        used_p.add(int(i))
        used_g.add(int(j))
        best[j] = iou[i, j]
        hit[i] = iou[i, j] >= iou_threshold
        if hit[i]:
            pairs.append((int(i), int(j)))
    tp = int((best >= iou_threshold).sum())
    n_ignored = 0
    if ignore is not None and n_pred:
        ig = np.asarray(ignore, np.float64).reshape(-1, 7)
        if len(ig):
            n_ignored = int((~hit & (box_iou_3d(pred, ig).max(axis=1) >= iou_threshold)).sum())
    n_counted = n_pred - n_ignored
    return {
        "tp": tp, "n_pred": n_counted, "n_gt": n_gt,
        "recall": tp / n_gt if n_gt else float("nan"),
        "precision": tp / n_counted if n_counted else float("nan"),
        "ious": best, "n_ignored": n_ignored, "pairs": pairs,
    }


def chamfer_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Chamfer distance [m]: ½ (mean_a min_b |a − b| + mean_b min_a |b − a|).

    Parameters
    ----------
    a : (N, ≥3), b : (M, ≥3) — point clouds; only x, y, z [m] are used. NaN if either is empty.
    """
    from scipy.spatial import cKDTree

    a = np.asarray(a, np.float64)[:, :3]
    b = np.asarray(b, np.float64)[:, :3]
    if not len(a) or not len(b):
        return float("nan")
    da, _ = cKDTree(b).query(a)
    db, _ = cKDTree(a).query(b)
    return float(0.5 * (da.mean() + db.mean()))


def doorway_visible_fraction(doorway_boxes_world: np.ndarray, camera_to_world: np.ndarray,
                             intrinsics, depth_m: np.ndarray, *, grid: tuple[int, int] = (16, 24),
                             occlusion_tol_m: float = 0.3) -> np.ndarray:
    """Fraction of each doorway's area that the camera sees (inside the image, not occluded).

    The doorway is the rectangle in the box's mid-plane spanned by its along-wall extent ``dx``
    and its height ``dz`` (for procedural worlds' doorway boxes: the door frame's outline in
    the wall). It is sampled on a ``grid`` (rows × columns) of points; a point counts as seen
    when it projects inside the image in front of the camera and the depth map there is not
    nearer than the point by more than ``occlusion_tol_m`` (an open doorway shows the room
    behind it, which is farther — still seen; a wall corner or prop in front hides it).

    Parameters
    ----------
    doorway_boxes_world : (M, 7) — ``x y z dx dy dz heading`` [m, rad], world frame, z up.
    camera_to_world : (4, 4) — OpenCV camera (x right, y down, z forward) to world.
    intrinsics : CameraIntrinsics — ``fx fy cx cy width height``.
    depth_m : (H, W) — z-depth of the frame [m], 0 where no surface.

    Returns
    -------
    (M,) float64 in [0, 1].
    """
    boxes = np.asarray(doorway_boxes_world, np.float64).reshape(-1, 7)
    if not len(boxes):
        return np.zeros(0)
    cam_from_world = np.linalg.inv(np.asarray(camera_to_world, np.float64))
    depth = np.asarray(depth_m, np.float64)
    h, w = depth.shape
    nr, nc = grid
    su = (np.arange(nc) + 0.5) / nc - 0.5
    sz = (np.arange(nr) + 0.5) / nr - 0.5
    uu, zz = np.meshgrid(su, sz)
    out = np.zeros(len(boxes))
    for i, (x, y, z, dx, _, dz, hd) in enumerate(boxes):
        pw = np.stack([x + uu.ravel() * dx * math.cos(hd), y + uu.ravel() * dx * math.sin(hd),
                       z + zz.ravel() * dz], axis=1)
        pc = pw @ cam_from_world[:3, :3].T + cam_from_world[:3, 3]
        front = pc[:, 2] > 0.05
        zc = np.where(front, pc[:, 2], 1.0)
        u = intrinsics.fx * pc[:, 0] / zc + intrinsics.cx
        v = intrinsics.fy * pc[:, 1] / zc + intrinsics.cy
        inside = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        ui = np.clip(u.astype(np.int64), 0, w - 1)
        vi = np.clip(v.astype(np.int64), 0, h - 1)
        d = depth[vi, ui]
        seen = inside & ((d <= 0) | ~np.isfinite(d) | (d >= pc[:, 2] - occlusion_tol_m))
        out[i] = seen.mean()
    return out


@dataclasses.dataclass
class ReconstructionScores:
    """Scores of one frame (or, after :func:`aggregate_scores`, of a set of frames)."""

    depth: dict
    segmentation: SegmentationCounts
    materials: MaterialCounts
    doors: dict
    radar: dict = dataclasses.field(default_factory=dict)
    timings_s: dict = dataclasses.field(default_factory=dict)

    def summary(self) -> dict[str, float]:
        """Flat dict of the headline figures."""
        out = {
            "abs_rel": self.depth.get("abs_rel", float("nan")),
            "delta_1_25": self.depth.get("delta_1_25", float("nan")),
            "miou": self.segmentation.miou(),
            "material_acc": self.materials.accuracy(),
            "door_recall@0.3": self.doors.get("recall", float("nan")),
            "door_precision@0.3": self.doors.get("precision", float("nan")),
            "door_mean_iou": self.doors.get("mean_iou", float("nan")),
        }
        out.update({f"radar_{k}": v for k, v in self.radar.items()})
        if self.timings_s:
            out["seconds"] = self.timings_s.get("total", float("nan"))
        return out


def _gt(ground_truth, name):
    if isinstance(ground_truth, dict):
        return ground_truth.get(name)
    return getattr(ground_truth, name, None)


def score_reconstruction(scene, ground_truth, *, iou_threshold: float = 0.3,
                         radar_points: np.ndarray | None = None,
                         radar_points_gt: np.ndarray | None = None) -> ReconstructionScores:
    """Score a :class:`~sim2radar.reconstruct.LabeledScene` against a ``WorldFrame``-like truth.

    Parameters
    ----------
    scene : LabeledScene
    ground_truth : object or dict with ``depth_m``, ``semantic_id``, ``material_id``,
        ``camera_to_world``, ``radar_to_world``, ``door_boxes_radar`` and optionally
        ``door_visible`` (M,) bool (only visible doors count towards recall).
    radar_points, radar_points_gt : (N, ≥3) radar points simulated on the reconstructed and on
        the ground-truth geometry (same radar, same pose), if available.
    """
    depth = depth_metrics(scene.depth_m, _gt(ground_truth, "depth_m"))
    seg = segmentation_counts(scene.semantic_id, _gt(ground_truth, "semantic_id"))
    mat = material_counts(scene.material_id, _gt(ground_truth, "material_id"))
    gt_boxes = np.asarray(_gt(ground_truth, "door_boxes_radar"), np.float64).reshape(-1, 7)
    visible = _gt(ground_truth, "door_visible")
    if visible is not None:
        gt_boxes = gt_boxes[np.asarray(visible, bool)]
    radar_from_camera = (np.linalg.inv(np.asarray(_gt(ground_truth, "radar_to_world")))
                         @ np.asarray(_gt(ground_truth, "camera_to_world")))
    pred_boxes = scene.door_boxes_in(radar_from_camera)
    doors = match_boxes(pred_boxes, gt_boxes, iou_threshold)
    matched = doors["ious"][doors["ious"] > 0]
    doors["mean_iou"] = float(matched.mean()) if len(matched) else float("nan")
    radar = {}
    if radar_points is not None and radar_points_gt is not None:
        n_gt = len(radar_points_gt)
        radar = {"chamfer_m": chamfer_distance(radar_points, radar_points_gt),
                 "points_ratio": len(radar_points) / n_gt if n_gt else float("nan"),
                 "n_points": len(radar_points), "n_points_gt": n_gt}
    return ReconstructionScores(depth, seg, mat, doors, radar, dict(scene.timings_s))


def aggregate_scores(scores: list[ReconstructionScores]) -> ReconstructionScores:
    """Combine per-frame scores: depth averaged per pixel, IoU / accuracy counts summed, door
    matches pooled, radar figures averaged per frame."""
    if not scores:
        raise ValueError("aggregate_scores: no scores given")
    n_px = np.array([s.depth.get("n_px", 0) for s in scores], np.float64)
    w = n_px / n_px.sum() if n_px.sum() else np.full(len(scores), 1 / len(scores))
    depth = {}
    for k in ("abs_rel", "delta_1_25", "coverage"):
        vals = np.array([s.depth.get(k, np.nan) for s in scores])
        ok = np.isfinite(vals)
        depth[k] = float(np.sum(vals[ok] * w[ok]) / max(w[ok].sum(), 1e-12)) if ok.any() else float("nan")
    depth["n_px"] = int(n_px.sum())
    seg = scores[0].segmentation
    mat = scores[0].materials
    for s in scores[1:]:
        seg = seg + s.segmentation
        mat = mat + s.materials
    tp = sum(s.doors["tp"] for s in scores)
    n_gt = sum(s.doors["n_gt"] for s in scores)
    n_pred = sum(s.doors["n_pred"] for s in scores)
    ious = np.concatenate([s.doors["ious"] for s in scores]) if scores else np.zeros(0)
    matched = ious[ious > 0]
    doors = {"tp": tp, "n_gt": n_gt, "n_pred": n_pred,
             "recall": tp / n_gt if n_gt else float("nan"),
             "precision": tp / n_pred if n_pred else float("nan"),
             "ious": ious, "mean_iou": float(matched.mean()) if len(matched) else float("nan")}
    radar = {}
    keys = set().union(*(s.radar.keys() for s in scores))
    for k in sorted(keys):
        vals = np.array([s.radar.get(k, np.nan) for s in scores], np.float64)
        radar[k] = float(np.nanmean(vals)) if np.isfinite(vals).any() else float("nan")
    timings = {}
    for k in set().union(*(s.timings_s.keys() for s in scores)):
        timings[k] = float(np.mean([s.timings_s.get(k, 0.0) for s in scores]))
    return ReconstructionScores(depth, seg, mat, doors, radar, timings)
