"""The scene geometry the radar ray tracer builds on: meshes merged, poses checked (NumPy).

:class:`~sim2radar.radar.raytrace.RadarScene` merges all meshes of a scene into one triangle
soup (:func:`merge_meshes`) with a per-face material index (which Fresnel tables and roughness
coefficients a hit uses) and a per-face object index (:func:`face_object_ids`: a transmitted ray
leaves the object it entered), and checks every radar pose (:func:`check_pose`). Pure NumPy;
all three are re-exported by :mod:`sim2radar.radar.raytrace` and :mod:`sim2radar.radar`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sim2radar.em import get_material
from sim2radar.mesh import MaterialMesh

__all__ = ["check_pose", "face_object_ids", "merge_meshes", "mesh_list"]


def check_pose(pose: np.ndarray | None) -> np.ndarray:
    """Validate a (4, 4) radar-to-world transform (rigid); ``None`` -> identity."""
    if pose is None:
        return np.eye(4)
    m = np.asarray(pose, dtype=np.float64)
    if m.shape != (4, 4):
        raise ValueError(f"pose must be a (4, 4) radar-to-world matrix, got shape {m.shape}")
    if not np.isfinite(m).all():
        raise ValueError("pose contains NaN or inf")
    r = m[:3, :3]
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-4) or np.linalg.det(r) < 0:
        raise ValueError("pose[:3, :3] must be a rotation (orthonormal, det +1)")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise ValueError("pose last row must be [0, 0, 0, 1]")
    return m


def mesh_list(meshes: Sequence[MaterialMesh]) -> list[MaterialMesh]:
    """``meshes`` as a non-empty list of MaterialMesh (one mesh alone is a list of one)."""
    if isinstance(meshes, MaterialMesh):
        return [meshes]
    meshes = list(meshes)
    if not meshes:
        raise ValueError("the scene has no meshes; pass a non-empty list of MaterialMesh")
    for i, mesh in enumerate(meshes):
        if not isinstance(mesh, MaterialMesh):
            raise TypeError(f"meshes[{i}] is {type(mesh).__name__}, expected MaterialMesh")
    return meshes


def merge_meshes(
    meshes: Sequence[MaterialMesh],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """Concatenate meshes into one triangle soup with a per-face material index.

    Returns
    -------
    vertices : (V, 3) float32 [m]
    faces : (F, 3) uint32
    face_material : (F,) uint32 — index into ``materials``
    materials : list[str] — normalised material names
    """
    meshes = mesh_list(meshes)
    materials: list[str] = []
    verts, faces, mats = [], [], []
    offset = 0
    for i, mesh in enumerate(meshes):
        try:
            name = get_material(mesh.material).name
        except KeyError as exc:
            raise ValueError(f"meshes[{i}] ({mesh.name or 'unnamed'}): {exc}") from None
        if name not in materials:
            materials.append(name)
        verts.append(mesh.vertices)
        faces.append(mesh.faces.astype(np.int64) + offset)
        mats.append(np.full(len(mesh.faces), materials.index(name), dtype=np.uint32))
        offset += len(mesh.vertices)
    f = np.concatenate(faces)
    if len(f) == 0:
        raise ValueError("the scene's meshes have no faces")
    return (
        np.concatenate(verts).astype(np.float32),
        f.astype(np.uint32),
        np.concatenate(mats),
        materials,
    )


def face_object_ids(meshes: Sequence[MaterialMesh]) -> np.ndarray:
    """(F,) uint32 — the index of the mesh each face of :func:`merge_meshes` belongs to (one
    mesh = one object = one slab for transmission)."""
    meshes = mesh_list(meshes)
    return np.concatenate(
        [np.full(len(m.faces), i, dtype=np.uint32) for i, m in enumerate(meshes)]
    )
