"""Torch voxelisation against a plain-Python reference (spconv/OpenPCDet semantics)."""

from __future__ import annotations

import numpy as np
import torch

from sim2radar.detect.voxelize import voxelize

RANGE = (-1.0, -5.2, -1.5, 5.4, 5.2, 2.5)
VOXEL = (0.4, 0.4, 4.0)


def _reference(points: np.ndarray, max_pts: int, max_vox: int):
    """Dict (b, z, y, x) -> list of point rows, voxels in first-seen order, per frame limit."""
    lo, vs = np.array(RANGE[:3]), np.array(VOXEL)
    grid = np.round((np.array(RANGE[3:]) - lo) / vs).astype(int)
    vox: dict[tuple, list] = {}
    per_batch: dict[int, int] = {}
    for p in points:
        idx = np.floor((p[1:4] - lo) / vs).astype(int)
        if np.any(idx < 0) or np.any(idx >= grid):
            continue
        key = (int(p[0]), idx[2], idx[1], idx[0])
        if key not in vox:
            if per_batch.get(key[0], 0) >= max_vox:
                continue
            per_batch[key[0]] = per_batch.get(key[0], 0) + 1
            vox[key] = []
        if len(vox[key]) < max_pts:
            vox[key].append(p[1:])
    return vox


def _check(points: np.ndarray, max_pts: int, max_vox: int):
    pil = voxelize(torch.from_numpy(points), 2, RANGE, VOXEL, max_pts, max_vox)
    ref = _reference(points, max_pts, max_vox)
    assert pil.voxels.shape[0] == len(ref)
    for v in range(pil.voxels.shape[0]):
        key = tuple(int(c) for c in pil.coords[v])
        rows = np.array(ref[key])
        n = int(pil.num_points[v])
        assert n == len(rows)
        np.testing.assert_array_equal(pil.voxels[v, :n].numpy(), rows)
        assert torch.all(pil.voxels[v, n:] == 0)


def test_matches_reference_with_crowded_pillars_and_out_of_range_points():
    rng = np.random.default_rng(0)
    n = 3000
    pts = np.column_stack([
        rng.integers(0, 2, n).astype(np.float32),
        rng.uniform(-2, 6, n), rng.uniform(-6, 6, n), rng.uniform(-2, 3, n), rng.random(n),
    ]).astype(np.float32)
    pts[:200, 1:4] = [1.01, 0.01, 0.0]  # one crowded pillar: only the first 8 are kept
    pts = pts[np.argsort(pts[:, 0], kind="stable")]
    _check(pts, max_pts=8, max_vox=10_000)


def test_max_voxels_keeps_the_first_seen_pillars():
    rng = np.random.default_rng(1)
    n = 800
    pts = np.column_stack([
        np.repeat([0.0, 1.0], n // 2), rng.uniform(-1, 5.4, n), rng.uniform(-5.2, 5.2, n),
        rng.uniform(-1.5, 2.5, n), rng.random(n),
    ]).astype(np.float32)
    _check(pts, max_pts=32, max_vox=50)
    pil = voxelize(torch.from_numpy(pts), 2, RANGE, VOXEL, 32, 50)
    assert torch.bincount(pil.coords[:, 0]).tolist() == [50, 50]


def test_empty_input():
    pil = voxelize(torch.zeros(0, 5), 1, RANGE, VOXEL)
    assert pil.voxels.shape == (0, 32, 4) and pil.coords.shape == (0, 4)
