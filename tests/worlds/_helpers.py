"""Test helpers for world tests (small rig, point-to-triangle distance)."""

from __future__ import annotations

import numpy as np

from sim2radar.worlds import RigConfig

#: Small, fast rig used by most tests (64 x 48 px, 4 spp).
SMALL_RIG = RigConfig(width=64, height=48, spp=4, lidar_azimuth_step_deg=2.0)


def point_triangle_distance(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Distance [m] from each of (N, 3) points to the nearest of (F, 3, 3) triangles
    (Ericson, Real-Time Collision Detection, §5.1.5), vectorised over N x F."""
    p = np.asarray(points, np.float64)[:, None, :]
    a, b, c = (np.asarray(tris, np.float64)[None, :, i, :] for i in range(3))
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.sum(ab * ap, -1)
    d2 = np.sum(ac * ap, -1)
    bp = p - b
    d3 = np.sum(ab * bp, -1)
    d4 = np.sum(ac * bp, -1)
    cp = p - c
    d5 = np.sum(ab * cp, -1)
    d6 = np.sum(ac * cp, -1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    denom = va + vb + vc
    with np.errstate(divide="ignore", invalid="ignore"):
        v = vb / denom
        w = vc / denom
        closest = a + ab * v[..., None] + ac * w[..., None]  # interior
        # edge regions
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    e_ab = a + ab * np.clip(t_ab, 0, 1)[..., None]
    e_ac = a + ac * np.clip(t_ac, 0, 1)[..., None]
    e_bc = b + (c - b) * np.clip(t_bc, 0, 1)[..., None]
    # Ericson checks A, B, AB, C, AC, BC, interior in this order: apply in reverse (last wins)
    closest = np.where(((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0))[..., None], e_bc, closest)
    closest = np.where(((vb <= 0) & (d2 >= 0) & (d6 <= 0))[..., None], e_ac, closest)
    closest = np.where(((d6 >= 0) & (d5 <= d6))[..., None], c, closest)
    closest = np.where(((vc <= 0) & (d1 >= 0) & (d3 <= 0))[..., None], e_ab, closest)
    closest = np.where(((d3 >= 0) & (d4 <= d3))[..., None], b, closest)
    closest = np.where(((d1 <= 0) & (d2 <= 0))[..., None], a, closest)
    dist = np.linalg.norm(p - closest, axis=-1)
    return np.nan_to_num(dist, nan=np.inf).min(axis=1)
