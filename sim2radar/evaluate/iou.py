"""Rotated IoU of 3D boxes (BEV and 3D), vectorised in PyTorch on CPU or GPU.

Boxes follow the project layout (``sim2radar.vocab.BOX_FIELDS``): ``x y z dx dy dz heading``
in the radar frame (x forward, y left, z up), ``z`` the box centre [m], ``heading`` [rad]
about +z, ``dx`` measured along the heading. This is OpenPCDet's LiDAR box convention.

The BEV intersection of two rotated rectangles is the convex polygon spanned by (i) the corners
of each rectangle that lie inside the other and (ii) the pairwise edge intersections. The
candidate points are sorted by angle about their mean and the area follows from the shoelace
formula. Everything is batched over box pairs (no Python loop over boxes), so the same code
serves evaluation (float64, CPU) and rotated NMS (float32, CPU or CUDA).

The IoUs match an independent polygon computation (shapely) to 1e-6 (tests/evaluate/test_iou.py).
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = [
    "box_corners_bev",
    "paired_bev_intersection",
    "bev_iou",
    "iou_3d",
]

#: Pairs processed per chunk in the pairwise functions (bounds memory to ~100 MB).
_CHUNK_PAIRS = 262_144


def _as_tensor(boxes, dtype=None) -> tuple[torch.Tensor, bool]:
    """Return ``boxes`` as a (N, 7+) tensor and whether the input was NumPy."""
    if isinstance(boxes, torch.Tensor):
        t = boxes
        was_numpy = False
    else:
        t = torch.as_tensor(np.asarray(boxes, dtype=np.float64))
        was_numpy = True
    if t.ndim != 2 or t.shape[-1] < 7:
        raise ValueError(f"boxes must have shape (N, 7) [x y z dx dy dz heading], got {tuple(t.shape)}")
    if dtype is not None:
        t = t.to(dtype)
    return t, was_numpy


def _as_pair(boxes_a, boxes_b) -> tuple[torch.Tensor, torch.Tensor, bool]:
    """Both box sets as tensors of ``boxes_a``'s dtype and device; True if ``boxes_a`` was NumPy."""
    a, was_numpy = _as_tensor(boxes_a)
    b, _ = _as_tensor(boxes_b, dtype=a.dtype)
    return a, b.to(a.device), was_numpy


def box_corners_bev(boxes: torch.Tensor) -> torch.Tensor:
    """BEV corners of rotated boxes, counter-clockwise.

    Parameters
    ----------
    boxes : (N, 7) tensor — x, y, z, dx, dy, dz [m], heading [rad].

    Returns
    -------
    (N, 4, 2) tensor — corner x, y [m] in counter-clockwise order.
    """
    signs = boxes.new_tensor([[0.5, 0.5], [-0.5, 0.5], [-0.5, -0.5], [0.5, -0.5]])
    local = signs[None] * boxes[:, None, 3:5]  # (N, 4, 2)
    cos, sin = torch.cos(boxes[:, 6]), torch.sin(boxes[:, 6])
    x = local[..., 0] * cos[:, None] - local[..., 1] * sin[:, None]
    y = local[..., 0] * sin[:, None] + local[..., 1] * cos[:, None]
    return torch.stack([x, y], dim=-1) + boxes[:, None, 0:2]


def _inside(points: torch.Tensor, boxes: torch.Tensor, eps: float) -> torch.Tensor:
    """(K, P) mask: whether each of P points (K, P, 2) lies in the BEV rectangle of its box."""
    d = points - boxes[:, None, 0:2]
    cos, sin = torch.cos(boxes[:, 6])[:, None], torch.sin(boxes[:, 6])[:, None]
    lx = d[..., 0] * cos + d[..., 1] * sin
    ly = -d[..., 0] * sin + d[..., 1] * cos
    return (lx.abs() <= boxes[:, None, 3] / 2 + eps) & (ly.abs() <= boxes[:, None, 4] / 2 + eps)


def _cross(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def paired_bev_intersection(boxes_a: torch.Tensor, boxes_b: torch.Tensor) -> torch.Tensor:
    """BEV intersection area of box pairs ``(boxes_a[k], boxes_b[k])``.

    Parameters
    ----------
    boxes_a, boxes_b : (K, 7) tensors — boxes [m, rad], same dtype and device.

    Returns
    -------
    (K,) tensor — intersection area [m^2].
    """
    k = boxes_a.shape[0]
    if k == 0:
        return boxes_a.new_zeros(0)
    eps = 1e-6 if boxes_a.dtype == torch.float64 else 1e-4
    ca, cb = box_corners_bev(boxes_a), box_corners_bev(boxes_b)  # (K, 4, 2)
    a_in_b = _inside(ca, boxes_b, eps)
    b_in_a = _inside(cb, boxes_a, eps)
    # Edge-edge intersections: segment p + t r (A) against q + u s (B), t, u in [0, 1].
    p, r = ca, ca.roll(-1, dims=1) - ca
    q, s = cb, cb.roll(-1, dims=1) - cb
    p4, r4 = p[:, :, None], r[:, :, None]  # (K, 4, 1, 2)
    q4, s4 = q[:, None], s[:, None]  # (K, 1, 4, 2)
    denom = _cross(r4, s4)  # (K, 4, 4)
    qp = q4 - p4
    safe = torch.where(denom.abs() > 1e-12, denom, torch.ones_like(denom))
    t = _cross(qp, s4) / safe
    u = _cross(qp, r4) / safe
    e_valid = (denom.abs() > 1e-12) & (t >= -eps) & (t <= 1 + eps) & (u >= -eps) & (u <= 1 + eps)
    e_pts = (p4 + t[..., None] * r4).reshape(k, 16, 2)
    pts = torch.cat([ca, cb, e_pts], dim=1)  # (K, 24, 2)
    valid = torch.cat([a_in_b, b_in_a, e_valid.reshape(k, 16)], dim=1)  # (K, 24)
    count = valid.sum(dim=1)
    vf = valid.to(pts.dtype)
    centre = (pts * vf[..., None]).sum(dim=1) / count.clamp(min=1)[:, None].to(pts.dtype)
    rel = pts - centre[:, None]
    angle = torch.atan2(rel[..., 1], rel[..., 0])
    angle = torch.where(valid, angle, torch.full_like(angle, 10.0))  # invalid points sort last
    order = angle.argsort(dim=1)
    rel = torch.gather(rel, 1, order[..., None].expand(-1, -1, 2))
    valid_sorted = torch.gather(valid, 1, order)
    # Invalid (trailing) points repeat the first vertex: zero-length edges add no area.
    rel = torch.where(valid_sorted[..., None], rel, rel[:, :1].expand_as(rel))
    nxt = rel.roll(-1, dims=1)
    area = 0.5 * _cross(rel, nxt).sum(dim=1).abs()
    return torch.where(count >= 3, area, torch.zeros_like(area))


def _candidate_pairs(a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Index pairs whose circumscribed BEV circles overlap (all others have zero overlap)."""
    ra = 0.5 * torch.linalg.norm(a[:, 3:5], dim=1)
    rb = 0.5 * torch.linalg.norm(b[:, 3:5], dim=1)
    dist = torch.cdist(a[:, 0:2].contiguous(), b[:, 0:2].contiguous())
    return torch.nonzero(dist <= ra[:, None] + rb[None, :] + 1e-6, as_tuple=True)


def _pairwise_intersection(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """(N, M) BEV intersection areas [m^2], computed only for candidate pairs, in chunks."""
    inter = a.new_zeros(a.shape[0], b.shape[0])
    if a.shape[0] == 0 or b.shape[0] == 0:
        return inter
    ia, ib = _candidate_pairs(a, b)
    for start in range(0, ia.numel(), _CHUNK_PAIRS):
        sa, sb = ia[start : start + _CHUNK_PAIRS], ib[start : start + _CHUNK_PAIRS]
        inter[sa, sb] = paired_bev_intersection(a[sa], b[sb])
    return inter


def _finish(iou: torch.Tensor, was_numpy: bool):
    return iou.cpu().numpy() if was_numpy else iou


def bev_iou(boxes_a, boxes_b):
    """Pairwise rotated bird's-eye-view IoU.

    Parameters
    ----------
    boxes_a : (N, 7) array or tensor — boxes [m, rad].
    boxes_b : (M, 7) array or tensor — boxes [m, rad].

    Returns
    -------
    (N, M) IoU in [0, 1]; NumPy (float64) if ``boxes_a`` is NumPy, else a tensor.
    """
    a, b, was_numpy = _as_pair(boxes_a, boxes_b)
    inter = _pairwise_intersection(a[:, :7], b[:, :7])
    area_a = a[:, 3] * a[:, 4]
    area_b = b[:, 3] * b[:, 4]
    union = area_a[:, None] + area_b[None, :] - inter
    return _finish(inter / union.clamp(min=1e-12), was_numpy)


def iou_3d(boxes_a, boxes_b):
    """Pairwise rotated 3D IoU (rotation about z only, as in KITTI/OpenPCDet).

    ``IoU = A_bev_inter * h_overlap / (V_a + V_b - A_bev_inter * h_overlap)``, with ``z`` the
    box centre.

    Parameters
    ----------
    boxes_a : (N, 7) array or tensor — boxes [m, rad].
    boxes_b : (M, 7) array or tensor — boxes [m, rad].

    Returns
    -------
    (N, M) IoU in [0, 1]; NumPy (float64) if ``boxes_a`` is NumPy, else a tensor.
    """
    a, b, was_numpy = _as_pair(boxes_a, boxes_b)
    inter_bev = _pairwise_intersection(a[:, :7], b[:, :7])
    top = torch.minimum((a[:, 2] + a[:, 5] / 2)[:, None], (b[:, 2] + b[:, 5] / 2)[None, :])
    bottom = torch.maximum((a[:, 2] - a[:, 5] / 2)[:, None], (b[:, 2] - b[:, 5] / 2)[None, :])
    inter = inter_bev * (top - bottom).clamp(min=0)
    vol_a = a[:, 3] * a[:, 4] * a[:, 5]
    vol_b = b[:, 3] * b[:, 4] * b[:, 5]
    union = vol_a[:, None] + vol_b[None, :] - inter
    return _finish(inter / union.clamp(min=1e-12), was_numpy)
