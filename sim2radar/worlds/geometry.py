"""Small mesh builders for world generation: boxes, cylinders (:func:`sim2radar.mesh.
cylinder_arrays`, re-exported), merging, greedy rectangles.

All lengths in metres; meshes are closed and outward-facing.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sim2radar.mesh import MaterialMesh, box_mesh, cylinder_arrays

__all__ = ["box_arrays", "cylinder_arrays", "merge_arrays", "mesh_from_parts", "greedy_rects",
           "yaw_matrix"]


def yaw_matrix(yaw_rad: float) -> np.ndarray:
    """(3, 3) float64 rotation about +z by ``yaw_rad`` [rad]."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def box_arrays(
    center: Sequence[float], size: Sequence[float], heading_rad: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (8, 3) float64 and faces (12, 3) of a box (see :func:`sim2radar.mesh.box_mesh`)."""
    m = box_mesh(center, size, heading_rad, material="concrete")
    return m.vertices.astype(np.float64), m.faces.astype(np.int64)


def merge_arrays(parts: Sequence[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate (vertices, faces) parts into one vertex/face array pair."""
    verts, faces, offset = [], [], 0
    for v, f in parts:
        verts.append(np.asarray(v, dtype=np.float64))
        faces.append(np.asarray(f, dtype=np.int64) + offset)
        offset += len(v)
    return np.concatenate(verts), np.concatenate(faces)


def mesh_from_parts(
    parts: Sequence[tuple[np.ndarray, np.ndarray]], *, material: str, name: str, semantic: str
) -> MaterialMesh:
    """One :class:`MaterialMesh` from several (vertices, faces) parts."""
    v, f = merge_arrays(parts)
    return MaterialMesh(v, f, material=material, name=name, semantic=semantic)


def greedy_rects(mask: np.ndarray) -> list[tuple[int, int, int, int]]:
    """Cover a boolean (NX, NY) mask with axis-aligned rectangles of cells.

    Runs along axis 1 are merged with identical runs in consecutive rows of axis 0.

    Returns
    -------
    list of (i0, i1, j0, j1) — half-open cell index ranges.
    """
    mask = np.asarray(mask, dtype=bool)
    open_runs: dict[tuple[int, int], int] = {}
    rects: list[tuple[int, int, int, int]] = []
    nx = mask.shape[0]
    for i in range(nx + 1):
        runs: set[tuple[int, int]] = set()
        if i < nx:
            row = mask[i].astype(np.int8)
            d = np.diff(np.concatenate([[0], row, [0]]))
            starts = np.flatnonzero(d == 1)
            ends = np.flatnonzero(d == -1)
            runs = set(zip(starts.tolist(), ends.tolist(), strict=True))
        for run in sorted(set(open_runs) - runs):
            rects.append((open_runs.pop(run), i, run[0], run[1]))
        for run in sorted(runs - set(open_runs)):
            open_runs[run] = i
    return sorted(rects)
