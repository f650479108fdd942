"""PointPillars losses (OpenPCDet ``AnchorHeadTemplate`` + ``pcdet/utils/loss_utils.py``).

* classification: sigmoid focal loss, Lin et al., ICCV 2017, eq. 5 (alpha 0.25, gamma 2),
  normalised by the number of positive anchors;
* localisation: smooth-L1 (beta 1/9) on the residual targets, with the heading term replaced by
  ``sin(a - b) = sin a cos b - cos a sin b`` (SECOND, Yan et al. 2018, eq. 3);
* direction: 2-bin softmax cross-entropy on the heading's half-turn (SECOND §2.4).

Total = 1.0 * cls + 2.0 * loc + 0.2 * dir by default (``ModelConfig.*_weight``).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from sim2radar.detect.anchors import limit_period

__all__ = ["direction_targets", "sigmoid_focal_loss", "weighted_smooth_l1", "add_sin_difference"]


def sigmoid_focal_loss(
    logits: torch.Tensor, targets: torch.Tensor, alpha: float = 0.25, gamma: float = 2.0
) -> torch.Tensor:
    """Element-wise sigmoid focal loss ``-alpha_t (1 - p_t)^gamma log p_t`` (Lin et al., eq. 5).

    ``logits`` and one-hot ``targets`` have the same shape (..., C); returns that shape.
    """
    p = torch.sigmoid(logits)
    alpha_w = targets * alpha + (1 - targets) * (1 - alpha)
    pt = targets * (1 - p) + (1 - targets) * p  # 1 - p_t
    bce = F.binary_cross_entropy_with_logits(logits, targets, reduction="none")
    return alpha_w * pt.pow(gamma) * bce


def add_sin_difference(preds: torch.Tensor, targets: torch.Tensor, dim: int = 6):
    """Replace the heading channel by ``sin(p) cos(t)`` / ``cos(p) sin(t)`` (SECOND eq. 3)."""
    sp = torch.sin(preds[..., dim : dim + 1]) * torch.cos(targets[..., dim : dim + 1])
    st = torch.cos(preds[..., dim : dim + 1]) * torch.sin(targets[..., dim : dim + 1])
    preds = torch.cat([preds[..., :dim], sp, preds[..., dim + 1 :]], dim=-1)
    targets = torch.cat([targets[..., :dim], st, targets[..., dim + 1 :]], dim=-1)
    return preds, targets


def weighted_smooth_l1(
    preds: torch.Tensor, targets: torch.Tensor, beta: float, code_weights: torch.Tensor
) -> torch.Tensor:
    """Smooth-L1 (Girshick, ICCV 2015, eq. 3 with transition ``beta``) per code: (..., 7)."""
    diff = (preds - targets) * code_weights
    diff = torch.where(torch.isnan(targets), torch.zeros_like(diff), diff)
    n = diff.abs()
    if beta < 1e-5:
        return n
    return torch.where(n < beta, 0.5 * n**2 / beta, n - 0.5 * beta)


def direction_targets(
    anchors: torch.Tensor, box_targets: torch.Tensor, dir_offset: float, num_bins: int
) -> torch.Tensor:
    """Direction-bin index of each target heading (OpenPCDet ``get_direction_target``)."""
    rot = box_targets[..., 6] + anchors[..., 6]
    offset_rot = limit_period(rot - dir_offset, 0.0, 2 * math.pi)
    bins = torch.floor(offset_rot / (2 * math.pi / num_bins)).long()
    return bins.clamp(0, num_bins - 1)
