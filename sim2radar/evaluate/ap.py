"""KITTI-protocol average precision for 3D and BEV boxes (one class).

Protocol (Geiger et al., CVPR 2012, KITTI object devkit ``eval.cpp``; Simonelli et al.,
ICCV 2019, for the 40-point variant), as in OpenPCDet's ``kitti_object_eval_python/eval.py``:

1. Per frame, rotated IoU between every prediction and every ground-truth box (3D or BEV,
   :mod:`sim2radar.evaluate.iou`). A prediction can match a ground truth only if
   ``IoU > iou_threshold`` (strict, as in the devkit).
2. Candidate score thresholds are the scores of the true positives found when each ground
   truth takes the highest-scoring unassigned prediction that overlaps it (devkit
   ``compute_statistics_jit(compute_fp=False)``).
3. At each threshold ``t``, predictions with ``score >= t`` are matched again, each ground truth
   taking the unassigned prediction of largest overlap (devkit ``compute_fp=True``); unmatched
   predictions are false positives, unmatched ground truths false negatives.
4. Precision is interpolated, ``p_interp = max`` over thresholds of equal or higher recall, and
   averaged over 11 (R11) or 40 (R40) recall positions; AP in percent.

Two ways of choosing the thresholds (``thresholds=``):

``"devkit"`` (default) — the devkit's ``get_thresholds(scores, num_gt, num_sample_pts=41)``:
    walking the true-positive scores from the highest down (duplicates kept), a score becomes a
    threshold when its recall ``(i + 1) / num_gt`` is at least as close to the next target
    recall (0, 1/40, 2/40, ...) as the following score's recall is; each chosen threshold moves
    the target on by 1/40, and the lowest score is always chosen. The ``k``-th chosen threshold
    (0-based, at most 41) then *stands for* recall ``k / 40``: R40 averages the interpolated
    precision of thresholds 1..40, R11 that of thresholds 0, 4, ..., 40 (``get_mAP_R40``,
    ``get_mAP``), a missing threshold counting as precision 0. This is the number OpenPCDet
    prints, so AP from this module can be set beside the paper's.

    Small sets: the index-for-recall substitution assumes many ground truths. With fewer than
    ~40, every true positive becomes a threshold and threshold ``k`` (recall ``(k+1)/num_gt``)
    is read as recall ``k/40``, so AP is biased low: 10 perfectly detected boxes give
    R40 = 22.5 and R11 = 27.3, 40 give R40 = 97.5 and R11 = 90.9 (41 or more give 100).
    Compare devkit APs only between evaluations on the same ground truth (as the experiment's
    paired conditions are), and use ``"all"`` for absolute figures on small sets.

``"all"`` — every distinct true-positive score is a threshold and the interpolated precision is
    read at the exact recall positions ``{0, 0.1, ..., 1}`` (R11) or ``{1/40, ..., 1}`` (R40).
    It is exact on small sets (10 perfect boxes give 100) and close to the devkit on large
    ones, but not equal: the devkit always takes the lowest true-positive score as a threshold
    and reads it as one more recall step, so where the highest recall reached lies just below
    a recall position the devkit counts that position and ``"all"`` does not. On 20 synthetic
    test sets of ~300 boxes (155 frames, recall ~0.6-0.65), devkit minus ``"all"`` was
    -0.0 to +1.5 points for R40 (mean +1.2) and -0.3 to +5.0 points for R11 (mean +0.4).

KITTI's difficulty levels, ``DontCare`` regions and 2D-height filters do not apply to radar
door boxes and are not used.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim2radar.evaluate.iou import bev_iou, iou_3d

__all__ = ["average_precision", "devkit_thresholds", "evaluate_detections", "precision_recall"]

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


THRESHOLD_MODES = ("devkit", "all")
#: the devkit's number of sampled recall positions (``N_SAMPLE_PTS`` in ``eval.py``)
DEVKIT_SAMPLE_POINTS = 41


def devkit_thresholds(tp_scores: np.ndarray, num_gt: int,
                      num_sample_pts: int = DEVKIT_SAMPLE_POINTS) -> np.ndarray:
    """Score thresholds sampled at the devkit's recall steps (``get_thresholds`` in
    OpenPCDet's ``kitti_object_eval_python/eval.py``; see the module docstring).

    Parameters
    ----------
    tp_scores : (K,) — scores of all true positives (duplicates kept).
    num_gt : int — number of ground-truth boxes (> 0).
    num_sample_pts : int — sampled recall positions, 41 in the devkit (recall 0, 1/40, ..., 1).

    Returns
    -------
    (T,) float64 — thresholds in descending order, ``T <= num_sample_pts``.
    """
    scores = np.sort(np.asarray(tp_scores, dtype=np.float64).reshape(-1))[::-1]
    step = 1.0 / (num_sample_pts - 1.0)
    current_recall = 0.0
    out: list[float] = []
    last = scores.size - 1
    for i, score in enumerate(scores):
        l_recall = (i + 1) / num_gt
        r_recall = (i + 2) / num_gt if i < last else l_recall
        # skip this score if the next one's recall is closer to the target recall
        if i < last and (r_recall - current_recall) < (current_recall - l_recall):
            continue
        out.append(float(score))
        current_recall += step
    return np.asarray(out[:num_sample_pts], dtype=np.float64)


def _counts_at(overlaps: list[np.ndarray], scores: list[np.ndarray], iou_threshold: float,
               thresholds: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True positives and detections with ``score >= t`` for every threshold ``t``."""
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
        # number of relevant score levels >= t for each threshold
        k = np.searchsorted(-rel_scores, -thresholds, side="right")
        tp += np.where(k > 0, tp_rel[np.maximum(k - 1, 0)], 0)
    return tp, n_det


def _check_mode(thresholds: str) -> None:
    if thresholds not in THRESHOLD_MODES:
        raise ValueError(f"thresholds must be one of {THRESHOLD_MODES}, got {thresholds!r}")


def precision_recall(
    gt_boxes: Sequence,
    pred_boxes: Sequence,
    pred_scores: Sequence,
    iou_threshold: float = 0.3,
    metric: str = "3d",
    thresholds: str = "devkit",
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Precision and recall at the KITTI score thresholds (not interpolated).

    Parameters
    ----------
    gt_boxes : list of (M_i, 7) arrays — ground truth per frame [m, rad].
    pred_boxes : list of (K_i, 7) arrays — predictions per frame [m, rad].
    pred_scores : list of (K_i,) arrays — prediction confidences.
    iou_threshold : float — a match needs IoU strictly greater than this.
    metric : ``"3d"`` or ``"bev"``.
    thresholds : ``"devkit"`` (at most 41 thresholds sampled at the devkit's recall steps;
        threshold ``k`` stands for recall ``k/40``) or ``"all"`` (every distinct true-positive
        score). See the module docstring.

    Returns
    -------
    thresholds, precision, recall : (T,) arrays, thresholds in descending order.
    """
    _check_mode(thresholds)
    gts, preds, scores = _check_inputs(gt_boxes, pred_boxes, pred_scores, metric)
    num_gt = sum(g.shape[0] for g in gts)
    if num_gt == 0:
        raise ValueError("no ground-truth boxes in any frame: average precision is undefined")
    overlaps = [_overlaps(g, p, metric) for g, p in zip(gts, preds, strict=True)]
    tp_scores: list[float] = []
    for ov, sc in zip(overlaps, scores, strict=True):
        tp_scores += _tp_scores(ov, sc, iou_threshold)
    if thresholds == "devkit":
        thr = devkit_thresholds(np.asarray(tp_scores), num_gt)
    else:
        thr = np.unique(np.asarray(tp_scores, dtype=np.float64))[::-1]
    if thr.size == 0:
        return thr, np.zeros(0), np.zeros(0)
    tp, n_det = _counts_at(overlaps, scores, iou_threshold, thr)
    precision = tp / np.maximum(n_det, 1)
    recall = tp / num_gt
    return thr, precision, recall


def _recall_positions(recall_points: int) -> np.ndarray:
    if recall_points == 11:
        return np.linspace(0.0, 1.0, 11)
    if recall_points == 40:
        return np.arange(1, 41) / 40.0
    raise ValueError(f"recall_points must be 11 or 40, got {recall_points!r}")


def _interpolated_ap(precision: np.ndarray, recall: np.ndarray, recall_points: int) -> float:
    """``"all"`` mode: mean of ``p_interp(r) = max_{recall >= r} precision`` over the exact
    recall positions [%]."""
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


def _devkit_ap(precision: np.ndarray, recall_points: int) -> float:
    """``"devkit"`` mode: precision of the sampled thresholds (descending), padded with zeros to
    41 entries, interpolated as the running max towards lower thresholds; R40 averages entries
    1..40, R11 entries 0, 4, ..., 40 (``get_mAP_R40`` / ``get_mAP``) [%]."""
    _recall_positions(recall_points)
    prec = np.zeros(DEVKIT_SAMPLE_POINTS)
    prec[: precision.size] = precision[:DEVKIT_SAMPLE_POINTS]
    prec = np.maximum.accumulate(prec[::-1])[::-1]
    picked = prec[1:] if recall_points == 40 else prec[::4]
    return float(100.0 * picked.sum() / recall_points)


def _ap(precision: np.ndarray, recall: np.ndarray, recall_points: int, thresholds: str) -> float:
    if thresholds == "devkit":
        return _devkit_ap(precision, recall_points)
    return _interpolated_ap(precision, recall, recall_points)


def average_precision(
    gt_boxes: Sequence,
    pred_boxes: Sequence,
    pred_scores: Sequence,
    iou_threshold: float = 0.3,
    metric: str = "3d",
    recall_points: int = 40,
    thresholds: str = "devkit",
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
    thresholds : ``"devkit"`` (OpenPCDet's numbers; biased low below ~40 ground truths) or
        ``"all"`` (exact recall positions). See the module docstring.

    Returns
    -------
    float — AP [%], in [0, 100].
    """
    _recall_positions(recall_points)  # validate before the (slower) matching
    _check_mode(thresholds)
    _, precision, recall = precision_recall(
        gt_boxes, pred_boxes, pred_scores, iou_threshold=iou_threshold, metric=metric,
        thresholds=thresholds,
    )
    return _ap(precision, recall, recall_points, thresholds)


def evaluate_detections(
    gt_boxes: Sequence,
    pred_boxes: Sequence,
    pred_scores: Sequence,
    iou_thresholds: Sequence[float] = (0.3, 0.5),
    metrics: Sequence[str] = METRICS,
    recall_points: Sequence[int] = (11, 40),
    thresholds: str = "devkit",
) -> dict[str, float]:
    """All AP figures of the paper's protocol in one dict.

    Keys are ``f"{metric}_r{recall_points}@{iou}"``, e.g. ``"3d_r40@0.3"`` (the paper's
    headline number is ``"3d_r11@0.3"`` / ``"3d_r40@0.3"``). Values are AP [%].
    ``thresholds`` as in :func:`average_precision` (default ``"devkit"``).
    """
    _check_mode(thresholds)
    for n in recall_points:
        _recall_positions(n)
    out = {}
    for metric in metrics:
        for thr in iou_thresholds:
            _, precision, recall = precision_recall(
                gt_boxes, pred_boxes, pred_scores, iou_threshold=thr, metric=metric,
                thresholds=thresholds,
            )
            for n in recall_points:
                out[f"{metric}_r{n}@{thr:g}"] = _ap(precision, recall, n, thresholds)
    return out
