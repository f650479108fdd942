"""Rotated non-maximum suppression on CPU or GPU (pure PyTorch; OpenPCDet ``nms_gpu`` parity).

The pairwise rotated BEV IoU is computed on the boxes' device (:func:`sim2radar.evaluate.iou
.bev_iou`, only for pairs whose circumscribed circles touch); the greedy pass then walks the
score-sorted boxes once over a boolean overlap matrix.
"""

from __future__ import annotations

import numpy as np
import torch

from sim2radar.evaluate.iou import bev_iou

__all__ = ["rotated_nms"]


def rotated_nms(
    boxes: torch.Tensor,
    scores: torch.Tensor,
    iou_threshold: float,
    pre_max: int | None = None,
    post_max: int | None = None,
) -> torch.Tensor:
    """Greedy NMS with rotated BEV IoU.

    Parameters
    ----------
    boxes : (K, 7) tensor — ``x y z dx dy dz heading`` [m, rad].
    scores : (K,) tensor — confidences.
    iou_threshold : a box is suppressed by a higher-scored kept box if their BEV IoU exceeds this.
    pre_max : consider only the ``pre_max`` best-scored boxes.
    post_max : return at most this many boxes.

    Returns
    -------
    (L,) int64 tensor — indices into ``boxes`` of the kept boxes, by descending score.
    """
    if boxes.shape[0] == 0:
        return torch.zeros(0, dtype=torch.long, device=boxes.device)
    order = torch.argsort(scores, descending=True, stable=True)
    if pre_max is not None:
        order = order[:pre_max]
    over = (bev_iou(boxes[order, :7], boxes[order, :7]) > iou_threshold).cpu().numpy()
    n = over.shape[0]
    suppressed = np.zeros(n, dtype=bool)
    keep = []
    for i in range(n):
        if suppressed[i]:
            continue
        keep.append(i)
        if post_max is not None and len(keep) >= post_max:
            break
        suppressed |= over[i]
    return order[torch.as_tensor(keep, dtype=torch.long, device=boxes.device)]
