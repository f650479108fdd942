"""Stage 2 ``oracle`` backend: ground-truth instance masks and semantic labels."""

from __future__ import annotations

import numpy as np

from sim2radar.reconstruct._gt import gt_array, majority
from sim2radar.reconstruct.types import (
    SEGMENT_BACKENDS,
    DepthResult,
    FrameInput,
    ReconstructionInputError,
    Segments,
)
from sim2radar.vocab import SEMANTIC_CLASSES

__all__ = ["OracleSegments"]


@SEGMENT_BACKENDS.register("oracle")
class OracleSegments:
    """One segment per ground-truth instance, labelled with its majority semantic class.

    Parameters
    ----------
    ground_truth : ``WorldFrame``-like or dict with ``instance_id`` (H, W) int (−1/negative =
        none) and ``semantic_id`` (H, W) into ``vocab.SEMANTIC_CLASSES``. Without
        ``instance_id``, the connected components of ``semantic_id`` are the segments.
    """

    def __init__(self, ground_truth=None) -> None:
        self.ground_truth = ground_truth

    def segment(self, frame: FrameInput, depth: DepthResult) -> Segments:
        gt = self.ground_truth
        semantic = gt_array(gt, "semantic_id", frame, "segmentation").astype(np.int64)
        has_instance = (isinstance(gt, dict) and "instance_id" in gt) or (
            not isinstance(gt, dict) and getattr(gt, "instance_id", None) is not None
        )
        if has_instance:
            inst = gt_array(gt, "instance_id", frame, "segmentation").astype(np.int64)
            inst = np.where(semantic > 0, inst, -1)
        else:
            import cv2

            inst = np.full(semantic.shape, -1, np.int64)
            base = 0
            for cls in np.unique(semantic[semantic > 0]):
                n, lab = cv2.connectedComponents((semantic == cls).astype(np.uint8), connectivity=4)
                inst[lab > 0] = lab[lab > 0] + base - 1
                base += n - 1
        ids = np.unique(inst[inst >= 0])
        if ids.size == 0:
            raise ReconstructionInputError(f"{frame.name}: ground truth has no labelled pixels")
        remap = np.full(int(ids.max()) + 2, -1, np.int64)
        remap[ids] = np.arange(ids.size)
        seg = np.where(inst >= 0, remap[np.clip(inst, 0, None)], -1).astype(np.int32)
        winner, frac = majority(semantic, seg, ids.size)
        labels = tuple(SEMANTIC_CLASSES[int(w)] for w in winner)
        return Segments(seg, labels, np.ones(ids.size, np.float32) * frac)
