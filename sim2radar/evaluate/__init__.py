"""Evaluation: KITTI-protocol AP for 3D / BEV boxes, rotated IoU (and, from other modules,
reconstruction and sim-real gap metrics)."""

from sim2radar.evaluate.ap import average_precision, evaluate_detections, precision_recall
from sim2radar.evaluate.iou import bev_iou, iou_3d

__all__ = ["average_precision", "evaluate_detections", "precision_recall", "bev_iou", "iou_3d"]
from sim2radar.evaluate.gap import compute_gap, write_gap_report  # noqa: E402,F401
from sim2radar.evaluate.reconstruction import aggregate_scores, score_reconstruction  # noqa: E402,F401
