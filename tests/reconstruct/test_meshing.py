"""Depth-grid triangulation: coverage, cuts at depth discontinuities, decimation, orientation."""

from __future__ import annotations

import math

import numpy as np

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.backproject import points_from_depth
from sim2radar.reconstruct.meshing import (
    MeshingConfig,
    grid_triangulate,
    segment_meshes,
    simplify_mesh,
)

K = CameraIntrinsics.from_fov(64, 48, 60.0)


def _area(v, f):
    t = v[f].astype(np.float64)
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum()


def test_fronto_parallel_plane_area():
    p = points_from_depth(np.full((48, 64), 2.0, np.float32), K)
    v, f = grid_triangulate(p, np.ones((48, 64), bool), focal_px=K.fx)
    # grid of pixel centres spans (W-1) x (H-1) pixel pitches at 2 m
    expected = (63 * 2.0 / K.fx) * (47 * 2.0 / K.fy)
    assert abs(_area(v, f) / expected - 1) < 1e-4
    assert len(f) == 2 * 63 * 47


def test_no_triangle_bridges_a_depth_step():
    depth = np.full((48, 64), 2.0, np.float32)
    depth[:, 32:] = 4.0  # a door edge in front of a wall 2 m behind
    p = points_from_depth(depth, K)
    v, f = grid_triangulate(p, np.ones((48, 64), bool), focal_px=K.fx)
    z = v[f][..., 2]
    assert len(f) > 0
    assert np.all(np.ptp(z, axis=1) < 1e-5), "a triangle joins the 2 m and 4 m surfaces"


def test_grazing_floor_is_not_cut():
    # a floor 1.5 m below a level camera: depth grows fast towards the horizon but is continuous
    u = np.arange(64) + 0.5
    v = np.arange(48) + 0.5
    _, vv = np.meshgrid(u, v)
    y = (vv - K.cy) / K.fy
    depth = np.where(y > 0.02, 1.5 / np.maximum(y, 1e-6), 0).astype(np.float32)
    depth[depth > 12] = 0  # beyond 12 m the floor is seen at > 83 deg incidence
    p = points_from_depth(depth, K)
    valid = np.isfinite(p).all(-1)
    v_, f = grid_triangulate(p, valid, focal_px=K.fx)
    rows = valid.any(axis=1).sum()
    assert len(f) >= 0.98 * 2 * 63 * (rows - 1)


def test_simplify_keeps_a_plane_and_its_outline():
    p = points_from_depth(np.full((48, 64), 3.0, np.float32), K)
    v, f = grid_triangulate(p, np.ones((48, 64), bool), focal_px=K.fx)
    v2, f2 = simplify_mesh(v, f, 50)
    assert len(f2) <= 60
    assert abs(_area(v2, f2) / _area(v, f) - 1) < 0.01
    np.testing.assert_allclose(v2.min(0)[:2], v.min(0)[:2], atol=1e-4)
    np.testing.assert_allclose(v2.max(0)[:2], v.max(0)[:2], atol=1e-4)


def test_segment_meshes_face_the_camera_and_carry_labels():
    depth = np.full((48, 64), 2.5, np.float32)
    seg = np.zeros((48, 64), np.int32)
    seg[:, 40:] = 1
    seg[:5, :5] = -1
    p = points_from_depth(depth, K)
    meshes = segment_meshes(p, seg, ("wall", "door"), ["concrete", "metal"], K.fx,
                            MeshingConfig(stride_px=2, target_faces=20))
    assert [m.semantic for m in meshes] == ["wall", "door"]
    assert [m.material for m in meshes] == ["concrete", "metal"]
    for m in meshes:
        centroids = m.triangles.mean(axis=1)
        assert np.all(np.sum(m.face_normals * centroids, axis=1) < 0)
    door = meshes[1]
    # door spans columns 40..63 at 2.5 m: x from (40.5 - cx) / fx * 2.5
    assert math.isclose(door.bounds[0, 0], (40.5 - K.cx) / K.fx * 2.5, abs_tol=1e-3)
