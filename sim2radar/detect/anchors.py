"""Anchors, the residual box coder and the axis-aligned target assigner (OpenPCDet parity).

References: OpenPCDet ``pcdet/models/dense_heads/target_assigner/anchor_generator.py``,
``axis_aligned_target_assigner.py`` and ``pcdet/utils/box_coder_utils.py::ResidualCoder``;
the encoding is SECOND's (Yan et al., Sensors 2018, eq. 1).
"""

from __future__ import annotations

import math

import torch

from sim2radar.detect.config import ModelConfig

__all__ = [
    "assign_targets",
    "decode_boxes",
    "encode_boxes",
    "generate_anchors",
    "limit_period",
    "nearest_bev_iou",
]


def limit_period(val: torch.Tensor, offset: float = 0.5, period: float = math.pi) -> torch.Tensor:
    """Wrap ``val`` into ``[-offset * period, (1 - offset) * period)``."""
    return val - torch.floor(val / period + offset) * period


def generate_anchors(cfg: ModelConfig, device=None, dtype=torch.float32) -> torch.Tensor:
    """Anchors for the head's feature map, in the head's output order.

    Returns
    -------
    (H * W * R, 7) tensor — ``x y z dx dy dz heading`` [m, rad] for feature rows (y) H, columns
    (x) W and R rotations, flattened in (y, x, rotation) order (OpenPCDet ``AnchorGenerator``).
    """
    nx, ny, _ = cfg.grid_size
    stride = cfg.feature_map_stride
    fx, fy = nx // stride, ny // stride
    r = cfg.point_cloud_range_m
    a = cfg.anchor
    if a.align_center:
        xs, ys = (r[3] - r[0]) / fx, (r[4] - r[1]) / fy
        x = r[0] + xs / 2 + xs * torch.arange(fx, device=device, dtype=torch.float64)
        y = r[1] + ys / 2 + ys * torch.arange(fy, device=device, dtype=torch.float64)
    else:
        x = torch.linspace(r[0], r[3], fx, device=device, dtype=torch.float64)
        y = torch.linspace(r[1], r[4], fy, device=device, dtype=torch.float64)
    rot = torch.tensor(a.rotations_rad, device=device, dtype=torch.float64)
    yy, xx, rr = torch.meshgrid(y, x, rot, indexing="ij")  # (fy, fx, R)
    dx, dy, dz = a.size_m
    z = a.bottom_height_m + dz / 2
    anchors = torch.stack(
        [xx, yy, torch.full_like(xx, z), torch.full_like(xx, dx), torch.full_like(xx, dy),
         torch.full_like(xx, dz), rr],
        dim=-1,
    )
    return anchors.reshape(-1, 7).to(dtype)


def encode_boxes(boxes: torch.Tensor, anchors: torch.Tensor) -> torch.Tensor:
    """Residual encoding of boxes w.r.t. anchors (OpenPCDet ``ResidualCoder.encode_torch``).

    ``t_x = (x_g - x_a) / d_a``, ``t_y = (y_g - y_a) / d_a`` with ``d_a = sqrt(dx_a^2 + dy_a^2)``,
    ``t_z = (z_g - z_a) / dz_a``, ``t_dx = log(dx_g / dx_a)`` (same for dy, dz),
    ``t_h = h_g - h_a``. Shapes (..., 7) -> (..., 7).
    """
    anchors = anchors.clone()
    anchors[..., 3:6] = anchors[..., 3:6].clamp(min=1e-5)
    boxes = boxes.clone()
    boxes[..., 3:6] = boxes[..., 3:6].clamp(min=1e-5)
    xa, ya, za, dxa, dya, dza, ra = anchors.unbind(-1)
    xg, yg, zg, dxg, dyg, dzg, rg = boxes.unbind(-1)
    diag = torch.sqrt(dxa**2 + dya**2)
    return torch.stack(
        [(xg - xa) / diag, (yg - ya) / diag, (zg - za) / dza, torch.log(dxg / dxa),
         torch.log(dyg / dya), torch.log(dzg / dza), rg - ra],
        dim=-1,
    )


def decode_boxes(deltas: torch.Tensor, anchors: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`encode_boxes` (OpenPCDet ``ResidualCoder.decode_torch``)."""
    xa, ya, za, dxa, dya, dza, ra = anchors.unbind(-1)
    xt, yt, zt, dxt, dyt, dzt, rt = deltas.unbind(-1)
    diag = torch.sqrt(dxa**2 + dya**2)
    return torch.stack(
        [xt * diag + xa, yt * diag + ya, zt * dza + za, torch.exp(dxt) * dxa,
         torch.exp(dyt) * dya, torch.exp(dzt) * dza, rt + ra],
        dim=-1,
    )


def _nearest_bev(boxes: torch.Tensor) -> torch.Tensor:
    """(N, 7) boxes -> (N, 4) axis-aligned BEV boxes x1, y1, x2, y2 of the nearest alignment:
    headings within 45 degrees of the y axis swap dx and dy (OpenPCDet
    ``boxes3d_nearest_bev_iou``)."""
    rot = limit_period(boxes[:, 6], offset=0.5, period=math.pi).abs()
    swap = rot > math.pi / 4
    dx = torch.where(swap, boxes[:, 4], boxes[:, 3])
    dy = torch.where(swap, boxes[:, 3], boxes[:, 4])
    return torch.stack(
        [boxes[:, 0] - dx / 2, boxes[:, 1] - dy / 2, boxes[:, 0] + dx / 2, boxes[:, 1] + dy / 2],
        dim=1,
    )


def nearest_bev_iou(boxes_a: torch.Tensor, boxes_b: torch.Tensor) -> torch.Tensor:
    """(N, M) IoU of the axis-aligned nearest BEV boxes (the target assigner's similarity)."""
    a, b = _nearest_bev(boxes_a), _nearest_bev(boxes_b)
    w = (torch.minimum(a[:, None, 2], b[None, :, 2]) - torch.maximum(a[:, None, 0], b[None, :, 0]))
    h = (torch.minimum(a[:, None, 3], b[None, :, 3]) - torch.maximum(a[:, None, 1], b[None, :, 1]))
    inter = w.clamp(min=0) * h.clamp(min=0)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    return inter / (area_a[:, None] + area_b[None, :] - inter).clamp(min=1e-6)


def _nearest_bev_batched(boxes: torch.Tensor) -> torch.Tensor:
    """(..., 7) boxes -> (..., 4) nearest axis-aligned BEV boxes (:func:`_nearest_bev`)."""
    rot = limit_period(boxes[..., 6], offset=0.5, period=math.pi).abs()
    swap = rot > math.pi / 4
    dx = torch.where(swap, boxes[..., 4], boxes[..., 3])
    dy = torch.where(swap, boxes[..., 3], boxes[..., 4])
    x, y = boxes[..., 0], boxes[..., 1]
    return torch.stack([x - dx / 2, y - dy / 2, x + dx / 2, y + dy / 2], dim=-1)


@torch.no_grad()
def assign_targets(
    anchors: torch.Tensor,
    gt_boxes: torch.Tensor,
    matched_threshold: float,
    unmatched_threshold: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Axis-aligned target assignment (OpenPCDet ``AxisAlignedTargetAssigner``, no sampling).

    Each anchor whose nearest-BEV IoU with some box is ``>= matched_threshold`` is positive, and
    every box's best anchor(s) are forced positive; anchors below ``unmatched_threshold`` are
    negative; the rest are ignored.

    The whole batch at once on the anchors' device: a (B, A, M) IoU tensor with padding masked,
    no per-frame loop and no host synchronisation (no ``nonzero``/boolean indexing), so on a GPU
    the assignment never waits for the host. Same labels, targets and weights as assigning
    frame by frame (``tests/detect/test_anchors.py`` compares with that reference).

    Parameters
    ----------
    anchors : (A, 7) tensor — anchors [m, rad].
    gt_boxes : (B, M, 8) tensor — boxes [m, rad] + class id (1-based; 0 marks padding).

    Returns
    -------
    labels : (B, A) int64 — class id for positives, 0 negative, -1 ignored.
    box_targets : (B, A, 7) — encoded targets (zero for non-positives).
    reg_weights : (B, A) — 1 for positives, else 0.
    """
    gt_boxes = gt_boxes.to(anchors.device)
    classes = gt_boxes[..., 7].long()                       # (B, M)
    valid = classes > 0
    a, b = _nearest_bev_batched(anchors), _nearest_bev_batched(gt_boxes[..., :7])
    w = (torch.minimum(a[None, :, None, 2], b[:, None, :, 2])
         - torch.maximum(a[None, :, None, 0], b[:, None, :, 0]))
    h = (torch.minimum(a[None, :, None, 3], b[:, None, :, 3])
         - torch.maximum(a[None, :, None, 1], b[:, None, :, 1]))
    inter = w.clamp(min=0) * h.clamp(min=0)                  # (B, A, M)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[..., 2] - b[..., 0]) * (b[..., 3] - b[..., 1])
    overlap = inter / (area_a[None, :, None] + area_b[:, None, :] - inter).clamp(min=1e-6)
    overlap = torch.where(valid[:, None, :], overlap, torch.full_like(overlap, -1.0))
    a_max, a_arg = overlap.max(dim=2)                       # (B, A): best box per anchor
    g_max = overlap.max(dim=1).values                       # (B, M): best anchor per box
    # a box's best anchor(s) are forced positive, unless it overlaps no anchor at all
    forced = ((overlap == g_max[:, None, :]) & (valid & (g_max > 0))[:, None, :]).any(dim=2)
    best_class = torch.gather(classes, 1, a_arg)             # (B, A)
    has_gt = valid.any(dim=1, keepdim=True)                 # (B, 1)
    fg = (forced | (a_max >= matched_threshold)) & has_gt
    labels = torch.full_like(best_class, -1)
    labels = torch.where(fg, best_class, labels)
    labels = torch.where(a_max < unmatched_threshold, torch.zeros_like(labels), labels)
    labels = torch.where(forced, best_class, labels)
    labels = torch.where(has_gt, labels, torch.zeros_like(labels))
    matched = torch.gather(gt_boxes[..., :7], 1, a_arg[..., None].expand(-1, -1, 7))
    encoded = encode_boxes(matched, anchors.expand_as(matched))
    targets = torch.where(fg[..., None], encoded, torch.zeros_like(encoded))
    return labels, targets, fg.to(anchors.dtype)
