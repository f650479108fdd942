"""Pillar voxelisation in pure PyTorch (no spconv), batched, on CPU or GPU.

Same semantics as OpenPCDet's ``VoxelGeneratorV2`` / spconv ``PointToVoxel``: points outside the
range are dropped; a voxel keeps its first ``max_points_per_voxel`` points in input order;
each frame keeps at most ``max_voxels`` voxels, those whose first point comes earliest.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

__all__ = ["Pillars", "voxelize"]


@dataclass(frozen=True)
class Pillars:
    """Voxelised batch.

    Attributes
    ----------
    voxels : (P, M, C) float — point features per pillar, zero-padded; C = point columns
        (x, y, z [m], extra features), M = max points per pillar.
    num_points : (P,) int64 — valid points per pillar (1..M).
    coords : (P, 4) int64 — batch index, z, y, x voxel indices.
    batch_size : int — frames in the batch.
    """

    voxels: torch.Tensor
    num_points: torch.Tensor
    coords: torch.Tensor
    batch_size: int


@torch.no_grad()
def voxelize(
    points: torch.Tensor,
    batch_size: int,
    point_cloud_range_m: tuple[float, ...],
    voxel_size_m: tuple[float, float, float],
    max_points_per_voxel: int = 32,
    max_voxels: int = 16000,
) -> Pillars:
    """Group points into pillars.

    Parameters
    ----------
    points : (N, 1 + C) float — batch index, then x, y, z [m] and extra features per point.
    batch_size : number of frames (batch indices are in ``[0, batch_size)``).
    point_cloud_range_m : (x_min, y_min, z_min, x_max, y_max, z_max) [m].
    voxel_size_m : (vx, vy, vz) [m].
    max_points_per_voxel : points kept per pillar.
    max_voxels : pillars kept per frame.

    Returns
    -------
    Pillars
    """
    device = points.device
    lo = torch.tensor(point_cloud_range_m[:3], device=device, dtype=points.dtype)
    hi = torch.tensor(point_cloud_range_m[3:], device=device, dtype=points.dtype)
    vs = torch.tensor(voxel_size_m, device=device, dtype=points.dtype)
    grid = torch.round((hi - lo) / vs).long()  # nx, ny, nz
    nx, ny, nz = (int(g) for g in grid.tolist())

    xyz = points[:, 1:4]
    idx = torch.floor((xyz - lo) / vs).long()
    inside = ((idx >= 0) & (idx < grid)).all(dim=1)
    points, idx = points[inside], idx[inside]
    batch = points[:, 0].long()
    key = ((batch * nz + idx[:, 2]) * ny + idx[:, 1]) * nx + idx[:, 0]

    key_sorted, order = torch.sort(key, stable=True)
    uniq, inverse, counts = torch.unique_consecutive(key_sorted, return_inverse=True,
                                                     return_counts=True)
    start = torch.cumsum(counts, 0) - counts
    rank = torch.arange(key_sorted.numel(), device=device) - start[inverse]

    # Per frame, keep the max_voxels voxels whose first point comes first (spconv order).
    vox_batch = uniq // (nz * ny * nx)
    if uniq.numel() and torch.bincount(vox_batch, minlength=batch_size).max() > max_voxels:
        first = order[start]  # index of each voxel's first point
        vorder = torch.argsort(vox_batch * (points.shape[0] + 1) + first)
        per_batch = torch.bincount(vox_batch, minlength=batch_size)
        b_start = torch.cumsum(per_batch, 0) - per_batch
        vrank = torch.empty_like(vorder)
        vrank[vorder] = torch.arange(vorder.numel(), device=device) - b_start[vox_batch[vorder]]
        keep_v = vrank < max_voxels
        remap = torch.cumsum(keep_v.long(), 0) - 1
        keep_p = keep_v[inverse]
        inverse, rank = remap[inverse[keep_p]], rank[keep_p]
        order = order[keep_p]
        uniq, counts = uniq[keep_v], counts[keep_v]

    sel = rank < max_points_per_voxel
    voxels = points.new_zeros(uniq.numel(), max_points_per_voxel, points.shape[1] - 1)
    voxels[inverse[sel], rank[sel]] = points[order[sel], 1:]
    num_points = counts.clamp(max=max_points_per_voxel)
    rest = uniq
    x = rest % nx
    rest = rest // nx
    y = rest % ny
    rest = rest // ny
    z = rest % nz
    b = rest // nz
    coords = torch.stack([b, z, y, x], dim=1)
    return Pillars(voxels=voxels, num_points=num_points, coords=coords, batch_size=batch_size)
