"""KITTI-protocol average precision for 3D and BEV boxes (one class).

Protocol (Geiger et al., CVPR 2012, KITTI object devkit ``eval.cpp``; Simonelli et al.,
ICCV 2019, for the 40-point variant), as in OpenPCDet's ``kitti_object_eval_python``:

1. Per frame, rotated IoU between every prediction and every ground-truth box (3D or BEV,
   :mod:`sim2radar.evaluate.iou`). A prediction can match a ground truth only if
   ``IoU > iou_threshold`` (strict, as in the devkit).
2. Score thresholds are the scores of the true positives found when each ground truth takes
   the highest-scoring unassigned prediction that overlaps it (devkit ``compute_fp=False``).
3. At each threshold ``t``, predictions with ``score >= t`` are matched again, each ground truth
   taking the unassigned prediction of largest overlap (devkit ``compute_fp=True``); unmatched
   predictions are false positives, unmatched ground truths false negatives.
4. Precision is interpolated, ``p_interp(r) = max_{r' >= r} p(r')``, and averaged over the
   recall positions ``{0, 0.1, ..., 1}`` (R11) or ``{1/40, 2/40, ..., 1}`` (R40); AP in percent.

Difference from the devkit: the devkit subsamples the thresholds to ~41 recall steps
(``get_thresholds``), which assumes thousands of ground truths and under-reports AP on small
sets (e.g. 10 perfectly detected boxes give R40 = 22.5 there). Here every true-positive score
is a threshold and precision is read at the exact recall positions, which equals the devkit on
large sets and stays exact on small ones. KITTI's difficulty levels, ``DontCare`` regions and
2D-height filters do not apply to radar door boxes and are not used.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim2radar.evaluate.iou import bev_iou, iou_3d

__all__ = ["average_precision", "evaluate_detections", "precision_recall"]

METRICS = ("3d", "bev")


def _as_boxes(arr, what: str, frame: int) -> np.ndarray:
    a = np.asarray(arr, dtype=np.float64)
    if a.size == 0:
        return np.zeros((0, 7))
    if a.ndim != 2 or a.shape[1] < 7:
        raise ValueError(
            f"{what}[{frame}] must have shape (K, 7) [x y z dx dy dz heading], got {a.shape}"
        )
    if not np.all(np.isfinite(a[:, :7])):
        raise ValueError(f"{what}[{frame}] contains NaN or inf")
    return a[:, :7]


def _check_inputs(gt_boxes, pred_boxes, pred_scores, metric: str):
    if metric not in METRICS:
        raise ValueError(f"metric must be one of {METRICS}, got {metric!r}")
    if not (len(gt_boxes) == len(pred_boxes) == len(pred_scores)):
        raise ValueError(
            "gt_boxes, pred_boxes and pred_scores must be per-frame lists of equal length, got "
            f"{len(gt_boxes)}, {len(pred_boxes)}, {len(pred_scores)}"
        )
    gts, preds, scores = [], [], []
    for i, (g, p, s) in enumerate(zip(gt_boxes, pred_boxes, pred_scores, strict=True)):
        gts.append(_as_boxes(g, "gt_boxes", i))
        pb = _as_boxes(p, "pred_boxes", i)
        sc = np.asarray(s, dtype=np.float64).reshape(-1)
        if sc.shape[0] != pb.shape[0]:
            raise ValueError(
                f"frame {i}: {pb.shape[0]} predicted boxes but {sc.shape[0]} scores"
            )
        preds.append(pb)
        scores.append(sc)
    return gts, preds, scores


def _overlaps(gt: np.ndarray, pred: np.ndarray, metric: str) -> np.ndarray:
    """(D, G) IoU between predictions and ground truths of one frame."""
    if gt.shape[0] == 0 or pred.shape[0] == 0:
        return np.zeros((pred.shape[0], gt.shape[0]))
    return iou_3d(pred, gt) if metric == "3d" else bev_iou(pred, gt)


def _tp_scores(overlap: np.ndarray, scores: np.ndarray, thr: float) -> list[float]:
    """Devkit pass 1: each ground truth takes the best-scoring unassigned overlapping det."""
    assigned = np.zeros(overlap.shape[0], dtype=bool)
    out = []
    for i in range(overlap.shape[1]):
        cand = (~assigned) & (overlap[:, i] > thr)
        if cand.any():
            j = int(np.flatnonzero(cand)[np.argmax(scores[cand])])
            assigned[j] = True
            out.append(float(scores[j]))
    return out


def _tp_at(overlap: np.ndarray, scores: np.ndarray, thr: float, t: float) -> int:
    """Devkit pass 2 at score threshold ``t``: each ground truth takes the unassigned det
    (score >= t) of largest overlap. Returns the number of true positives."""
    active = scores >= t
    assigned = np.zeros(overlap.shape[0], dtype=bool)
    tp = 0
    for i in range(overlap.shape[1]):
        cand = active & (~assigned) & (overlap[:, i] > thr)
        if cand.any():
            j = int(np.flatnonzero(cand)[np.argmax(overlap[cand, i])])
            assigned[j] = True
            tp += 1
    return tp


def precision_recall(
    gt_boxes: Sequence,
    pred_boxes: Sequence,
    pred_scores: Sequence,
    iou_threshold: float = 0.3,
    metric: str = "3d",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Precision and recall at the KITTI score thresholds.

    Parameters
    ----------
    gt_boxes : list of (M_i, 7) arrays — ground truth per frame [m, rad].
    pred_boxes : list of (K_i, 7) arrays — predictions per frame [m, rad].
    pred_scores : list of (K_i,) arrays — prediction confidences.
    iou_threshold : float — a match needs IoU strictly greater than this.
    metric : ``"3d"`` or ``"bev"``.

    Returns
    -------
    thresholds, precision, recall : (T,) arrays, thresholds in descending order.
    """
    gts, preds, scores = _check_inputs(gt_boxes, pred_boxes, pred_scores, metric)
    num_gt = sum(g.shape[0] for g in gts)
    if num_gt == 0:
        raise ValueError("no ground-truth boxes in any frame: average precision is undefined")
    overlaps = [_overlaps(g, p, metric) for g, p in zip(gts, preds, strict=True)]
    tp_scores: list[float] = []
    for ov, sc in zip(overlaps, scores, strict=True):
        tp_scores += _tp_scores(ov, sc, iou_threshold)
    thresholds = np.unique(np.asarray(tp_scores))[::-1]
    if thresholds.size == 0:
        return thresholds, np.zeros(0), np.zeros(0)
    tp = np.zeros(thresholds.size)
    n_det = np.zeros(thresholds.size)
    for ov, sc in zip(overlaps, scores, strict=True):
        if sc.size == 0:
            continue
        # Count detections above every threshold at once.
        s_sorted = np.sort(sc)
        n_det += s_sorted.size - np.searchsorted(s_sorted, thresholds, side="left")
        # TP only changes when t crosses the score of a det that overlaps some GT.
        relevant = (ov > iou_threshold).any(axis=1) if ov.shape[1] else np.zeros(sc.size, bool)
        if not relevant.any():
            continue
        rel_scores = np.unique(sc[relevant])[::-1]  # descending
        tp_rel = np.array([_tp_at(ov, sc, iou_threshold, t) for t in rel_scores])
        # number of relevant score levels >= t for each global threshold
        k = np.searchsorted(-rel_scores, -thresholds, side="right")
        tp += np.where(k > 0, tp_rel[np.maximum(k - 1, 0)], 0)
    precision = tp / np.maximum(n_det, 1)
    recall = tp / num_gt
    return thresholds, precision, recall


def _recall_positions(recall_points: int) -> np.ndarray:
    if recall_points == 11:
        return np.linspace(0.0, 1.0, 11)
    if recall_points == 40:
        return np.arange(1, 41) / 40.0
    raise ValueError(f"recall_points must be 11 or 40, got {recall_points!r}")


def _interpolated_ap(precision: np.ndarray, recall: np.ndarray, recall_points: int) -> float:
    """Mean of ``p_interp(r) = max_{recall >= r} precision`` over the recall positions [%]."""
    positions = _recall_positions(recall_points)
    if precision.size == 0:
        return 0.0
    # running max from the end: best precision among thresholds with at least this recall
    order = np.argsort(recall, kind="stable")
    rec, prec = recall[order], precision[order]
    best_from = np.maximum.accumulate(prec[::-1])[::-1]
    idx = np.searchsorted(rec, positions - 1e-12, side="left")
    interp = np.where(idx < rec.size, best_from[np.minimum(idx, rec.size - 1)], 0.0)
    return float(100.0 * interp.mean())


def average_precision(
    gt_boxes: Sequence,
    pred_boxes: Sequence,
    pred_scores: Sequence,
    iou_threshold: float = 0.3,
    metric: str = "3d",
    recall_points: int = 40,
) -> float:
    """KITTI-protocol average precision, in percent.

    Parameters
    ----------
    gt_boxes : list of (M_i, 7) arrays — ground-truth boxes per frame, ``x y z dx dy dz
        heading`` [m, rad] (``z`` = box centre).
    pred_boxes : list of (K_i, 7) arrays — predicted boxes per frame, same layout.
    pred_scores : list of (K_i,) arrays — prediction confidences (any monotone scale).
    iou_threshold : float — minimum IoU (strict) for a true positive; the paper uses 0.3.
    metric : ``"3d"`` (rotated 3D IoU) or ``"bev"`` (rotated bird's-eye-view IoU).
    recall_points : 11 (R11: recall 0, 0.1, ..., 1) or 40 (R40: recall 1/40, ..., 1).

    Returns
    -------
    float — AP [%], in [0, 100].
    """
    _recall_positions(recall_points)  # validate before the (slower) matching
    _, precision, recall = precision_recall(
        gt_boxes, pred_boxes, pred_scores, iou_threshold=iou_threshold, metric=metric
    )
    return _interpolated_ap(precision, recall, recall_points)


def evaluate_detections(
    gt_boxes: Sequence,
    pred_boxes: Sequence,
    pred_scores: Sequence,
    iou_thresholds: Sequence[float] = (0.3, 0.5),
    metrics: Sequence[str] = METRICS,
    recall_points: Sequence[int] = (11, 40),
) -> dict[str, float]:
    """All AP figures of the paper's protocol in one dict.

    Keys are ``f"{metric}_r{recall_points}@{iou}"``, e.g. ``"3d_r40@0.3"`` (the paper's
    headline number is ``"3d_r11@0.3"`` / ``"3d_r40@0.3"``). Values are AP [%].
    """
    out = {}
    for metric in metrics:
        for thr in iou_thresholds:
            _, precision, recall = precision_recall(
                gt_boxes, pred_boxes, pred_scores, iou_threshold=thr, metric=metric
            )
            for n in recall_points:
                out[f"{metric}_r{n}@{thr:g}"] = _interpolated_ap(precision, recall, n)
    return out
