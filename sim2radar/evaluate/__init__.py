"""Evaluation: KITTI-protocol AP for 3D / BEV boxes, rotated IoU (and, from other modules,
reconstruction and sim-real gap metrics).

Names are imported on first use (PEP 562): the IoU and AP code needs torch (~1.2 s to import),
which a cached rerun's summary or a dataset figure does not.
"""

from __future__ import annotations

import importlib

__all__ = ["average_precision", "evaluate_detections", "precision_recall", "bev_iou", "iou_3d",
           "compute_gap", "write_gap_report", "aggregate_scores", "score_reconstruction"]

_MODULE_OF = {
    "average_precision": "ap", "evaluate_detections": "ap", "precision_recall": "ap",
    "bev_iou": "iou", "iou_3d": "iou",
    "compute_gap": "gap", "write_gap_report": "gap",
    "aggregate_scores": "reconstruction", "score_reconstruction": "reconstruction",
}


def __getattr__(name: str):
    if name in _MODULE_OF:
        module = importlib.import_module(f"sim2radar.evaluate.{_MODULE_OF[name]}")
        value = getattr(module, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'sim2radar.evaluate' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
