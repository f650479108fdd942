"""Back-projection, normals from depth, gravity and the level frame."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.backproject import (
    estimate_up,
    level_from_camera,
    normals_from_points,
    points_from_depth,
    transform_points,
)

K = CameraIntrinsics.from_fov(80, 60, 65.0)


def _rays(k: CameraIntrinsics) -> np.ndarray:
    u = np.arange(k.width) + 0.5
    v = np.arange(k.height) + 0.5
    uu, vv = np.meshgrid(u, v)
    return np.stack([(uu - k.cx) / k.fx, (vv - k.cy) / k.fy, np.ones_like(uu)], -1)


def _floor_depth(k: CameraIntrinsics, up_cam: np.ndarray, height_m: float) -> np.ndarray:
    """z-depth of a floor ``height_m`` below the camera (plane up·X = −height)."""
    r = _rays(k)
    denom = r @ up_cam
    with np.errstate(divide="ignore"):
        z = -height_m / denom
    return np.where(denom < -1e-6, z, 0).astype(np.float32)


def test_plane_back_projects_to_its_depth_and_extent():
    depth = np.full((K.height, K.width), 3.0, np.float32)
    p = points_from_depth(depth, K)
    assert p.shape == (60, 80, 3)
    np.testing.assert_allclose(p[..., 2], 3.0)
    # the outermost pixel centres span the field of view at 3 m: x = (u - cx) / fx * z
    half_width = 3.0 * math.tan(K.hfov_rad / 2)
    assert p[..., 0].max() == pytest.approx(half_width * (1 - 1 / K.width), rel=1e-4)
    assert p[..., 0].min() == pytest.approx(-half_width * (1 - 1 / K.width), rel=1e-4)


def test_invalid_depth_is_nan_and_shape_checked():
    depth = np.full((60, 80), 2.0, np.float32)
    depth[0, 0] = 0
    depth[1, 1] = np.nan
    depth[2, 2] = -1
    p = points_from_depth(depth, K)
    assert np.isnan(p[0, 0]).all() and np.isnan(p[1, 1]).all() and np.isnan(p[2, 2]).all()
    with pytest.raises(ValueError):
        points_from_depth(np.ones((60, 81), np.float32), K)


def test_normals_of_a_tilted_plane_face_the_camera():
    # plane through (0, 0, 4) with normal (0.3, -0.2, -1) normalised (facing the camera)
    n = np.array([0.3, -0.2, -1.0])
    n /= np.linalg.norm(n)
    r = _rays(K)
    z = (n @ np.array([0, 0, 4.0])) / (r @ n)
    p = points_from_depth(z.astype(np.float32), K)
    normals = normals_from_points(p, step_px=1)
    err = np.degrees(np.arccos(np.clip(normals.reshape(-1, 3) @ n, -1, 1)))
    assert np.nanmax(err) < 0.5


@pytest.mark.parametrize("pitch_deg", [0.0, 3.0, -8.0])
def test_up_vector_of_a_pitched_camera(pitch_deg):
    t = math.radians(pitch_deg)
    # a camera pitched down by t: world up expressed in camera coordinates
    up_true = np.array([0.0, -math.cos(t), -math.sin(t)])
    depth = _floor_depth(K, up_true, 1.3)
    normals = normals_from_points(points_from_depth(depth, K), step_px=1)
    up = estimate_up(normals)
    assert math.degrees(math.acos(np.clip(up @ up_true, -1, 1))) < 0.3


def test_level_frame_maps_up_to_z_and_the_view_to_x():
    up = np.array([0.0, -math.cos(0.1), -math.sin(0.1)])
    m = level_from_camera(up)
    np.testing.assert_allclose(m[:3, :3] @ up, [0, 0, 1], atol=1e-12)
    fwd = m[:3, :3] @ np.array([0, 0, 1.0])
    assert fwd[1] == pytest.approx(0, abs=1e-12) and fwd[0] > 0.99
    # camera x (right) becomes level -y (left is +y)
    assert (m[:3, :3] @ np.array([1.0, 0, 0]))[1] == pytest.approx(-1, abs=1e-9)
    np.testing.assert_allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-12)
    pts = transform_points(np.array([[0.0, 1.3, 0.0]]), m)  # 1.3 m "below" a level camera
    assert pts[0, 2] < -1.2
