"""The floor plane from raw LiDAR returns (``backproject.lidar_floor``), the check that its
returns lie on up-facing surfaces (``checked_floor``), the rig-height fallback (``find_floor``)
and the completion of the depth under the lowest beam down to the floor (``extend_to_floor``).

The LiDAR is ray-cast analytically: 16 beams from −15° to +15° elevation, a full turn in 1°
steps, 1.25 m above the floor of a corridor 3 m wide and 2.8 m high with end walls 12 m away,
on a camera pitched and rolled by a few degrees (OpenCV camera frame, looking along the
corridor).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.reconstruct.backproject import (
    FloorPlane,
    checked_floor,
    extend_to_floor,
    find_floor,
    lidar_floor,
    points_from_depth,
)
from tests.reconstruct._models import rotation_deg

HEIGHT = 1.25


def _world_to_camera(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """World (x along the corridor, y left, z up) to the OpenCV camera frame, tilted."""
    base = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    return rotation_deg(2, roll_deg) @ rotation_deg(0, pitch_deg) @ base


def _corridor_returns(pitch_deg=4.0, roll_deg=-3.0, extra=None):
    """LiDAR returns in the camera frame and the true up (camera frame)."""
    el = np.radians(np.linspace(-15.0, 15.0, 16))
    az = np.radians(np.arange(0.0, 360.0, 1.0))
    e, a = np.meshgrid(el, az)
    d = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)
    planes = [((0, 0, 1.0), -HEIGHT), ((0, 0, -1.0), -(2.8 - HEIGHT)),
              ((0, -1.0, 0), -1.5), ((0, 1.0, 0), -1.5), ((-1.0, 0, 0), -12.0), ((1.0, 0, 0), -12.0)]
    t = np.full(len(d), np.inf)
    for n, off in planes:
        with np.errstate(divide="ignore"):
            ti = off / (d @ np.asarray(n))
        t = np.where((ti > 0) & (ti < t), ti, t)
    pts = d * t[:, None]
    if extra is not None:
        pts = np.concatenate([pts, extra])
    r = _world_to_camera(pitch_deg, roll_deg)
    return (pts @ r.T).astype(np.float32), r @ np.array([0.0, 0.0, 1.0])


def _angle_deg(a, b):
    return math.degrees(math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def _guess(up, deg=3.0):
    """``up`` turned by ``deg`` about an axis perpendicular to it (the normals' estimate)."""
    axis = np.cross(up, [1.0, 0.0, 0.0])
    axis /= np.linalg.norm(axis)
    th = math.radians(deg)
    return up * math.cos(th) + np.cross(axis, up) * math.sin(th)


def test_floor_plane_fixes_tilt_and_height_from_a_rough_up():
    """From an up 3° off, the floor's normal comes back within 0.05° of the true up and the
    camera height within 5 mm; the returns of the floor ring span metres, so the tilt is
    fixed."""
    pts, up = _corridor_returns()
    floor = lidar_floor(pts, _guess(up))
    assert floor is not None
    assert _angle_deg(floor.normal, up) < 0.05
    assert floor.height_m == pytest.approx(HEIGHT, abs=0.005)
    assert floor.tilt_fixed and floor.spread_m > 2.0
    # every inlier lies within the tolerance (3 cm + 0.3 % of range) of the true floor:
    # floor returns, and wall returns just above the wall's foot
    tol = 0.03 + 0.003 * np.linalg.norm(floor.inliers, axis=1) + 1e-3
    assert (np.abs(floor.inliers @ up + HEIGHT) < tol).all()
    assert np.median(np.abs(floor.inliers @ up + HEIGHT)) < 0.005


def test_a_table_top_with_more_returns_is_not_the_floor():
    """A 1 m² table top 0.5 m above the floor with more returns than the floor ring is
    rejected: the floor's returns lie under it, and nothing lies under a floor."""
    gen = np.random.default_rng(0)
    table = np.column_stack([gen.uniform(2.0, 3.0, 3000), gen.uniform(-0.5, 0.5, 3000),
                             np.full(3000, 0.5 - HEIGHT)])
    pts, up = _corridor_returns(extra=table)
    floor = lidar_floor(pts, _guess(up, 1.0))
    assert floor is not None
    assert floor.height_m == pytest.approx(HEIGHT, abs=0.005)


def test_no_floor_returns_no_floor():
    """Returns from the walls and the ceiling only (the floor cut away): no plane."""
    pts, up = _corridor_returns()
    pts = pts[pts @ up > -HEIGHT + 0.05]
    assert lidar_floor(pts, up) is None


def test_the_floor_is_kept_only_on_up_facing_surfaces():
    """The floor plane is used only when the depth map's normals at its returns face up:
    the same returns over a map of wall normals (facing the camera) are rejected."""
    pts, up = _corridor_returns(pitch_deg=8.0, roll_deg=0.0)
    floor = lidar_floor(pts, up)
    k = CameraIntrinsics.from_fov(320, 240, 90.0)
    normals = np.broadcast_to(up.astype(np.float32), (240, 320, 3)).copy()
    assert checked_floor(floor, normals, k) is floor
    walls = np.broadcast_to(np.array([0.0, 0.0, -1.0], np.float32), (240, 320, 3)).copy()
    assert checked_floor(floor, walls, k) is None
    assert checked_floor(None, normals, k) is None
    assert isinstance(floor, FloorPlane)


def test_find_floor_falls_back_to_the_rig_height_only_without_floor_returns():
    """Facing a near wall, a LiDAR's lowest beam reaches no floor: with the rig's camera height
    the floor is ``up · p = −h`` (source "rig"), without it there is none. Returns that do
    measure the floor win over the rig height; returns behind the camera are not used (the
    depth map cannot check them)."""
    pts, up = _corridor_returns(pitch_deg=8.0, roll_deg=0.0)
    k = CameraIntrinsics.from_fov(320, 240, 90.0)
    normals = np.broadcast_to(up.astype(np.float32), (240, 320, 3)).copy()
    measured = find_floor(normals, up, k, pts, camera_height_m=1.6)
    assert measured.source == "lidar" and measured.height_m == pytest.approx(HEIGHT, abs=0.005)
    # the view filled by a wall (normals facing the camera), no floor returns
    walls = np.broadcast_to(np.array([0.0, 0.0, -1.0], np.float32), (240, 320, 3)).copy()
    no_floor = pts[pts @ up > -HEIGHT + 0.05]
    rig = find_floor(walls, up, k, no_floor, camera_height_m=1.6)
    assert rig.source == "rig" and rig.height_m == 1.6 and not rig.tilt_fixed
    assert np.allclose(rig.normal, up / np.linalg.norm(up))
    assert find_floor(walls, up, k, no_floor) is None
    behind = pts[pts[:, 2] < 0]
    assert find_floor(normals, up, k, behind) is None
    assert find_floor(normals, up, k, None, camera_height_m=1.6).source == "rig"
    assert FloorPlane.from_info(rig.to_info()).height_m == 1.6


def _corridor_depth(k: CameraIntrinsics, pitch_deg: float) -> tuple[np.ndarray, np.ndarray,
                                                                     np.ndarray]:
    """Exact z-depth of the test corridor seen by a camera 1.25 m up, pitched down, looking along
    it; the height above the floor of each pixel's point [m]; and the camera-frame up."""
    r = _world_to_camera(pitch_deg, 0.0)
    rays = points_from_depth(np.ones((k.height, k.width), np.float32), k).reshape(-1, 3)
    d = rays.astype(np.float64) @ r  # world directions
    planes = [((0, 0, 1.0), -HEIGHT), ((0, 0, -1.0), -(2.8 - HEIGHT)),
              ((0, -1.0, 0), -1.5), ((0, 1.0, 0), -1.5), ((-1.0, 0, 0), -6.0)]
    t = np.full(len(d), np.inf)
    for n, off in planes:
        with np.errstate(divide="ignore"):
            ti = off / (d @ np.asarray(n))
        t = np.where((ti > 0) & (ti < t), ti, t)
    height = (d[:, 2] * t + HEIGHT).reshape(k.height, k.width)
    return t.reshape(k.height, k.width).astype(np.float32), height, r @ np.array([0, 0, 1.0])


def test_extend_to_floor_completes_the_band_under_the_lowest_beam():
    """Depth known only 0.6 m above the floor (where a LiDAR's beams reach): continuing each
    column's lowest surface down to the floor, then the floor, gives the true depth of the
    walls' feet, the end wall's foot and the near floor within 1 % (camera pitched 3°)."""
    k = CameraIntrinsics.from_fov(160, 120, 70.0)
    truth, height, up = _corridor_depth(k, 3.0)
    depth = np.where(height > 0.6, truth, 0).astype(np.float32)
    band = depth == 0
    assert band.mean() > 0.2
    floor = FloorPlane(up, HEIGHT, np.zeros((0, 3), np.float32), 0.0, False, "rig")
    out, filled = extend_to_floor(depth, k, floor)
    assert (filled == band).all()
    rel = np.abs(out[band] - truth[band]) / truth[band]
    assert np.percentile(rel, 99) < 0.01, np.percentile(rel, 99)
    assert (out[~band] == depth[~band]).all()  # measured depth above the floor is kept


def test_extend_to_floor_puts_points_below_the_floor_back_on_it():
    """Depth extrapolated from the end wall over the floor puts floor pixels under the floor:
    each such pixel's ray meets the floor first, and gets that depth."""
    k = CameraIntrinsics.from_fov(160, 120, 70.0)
    truth, height, up = _corridor_depth(k, 3.0)
    on_floor = height < 1e-6
    depth = np.where(on_floor, 6.0, truth).astype(np.float32)  # the end wall's depth
    floor = FloorPlane(up, HEIGHT, np.zeros((0, 3), np.float32), 0.0, False, "rig")
    out, filled = extend_to_floor(depth, k, floor)
    assert filled[on_floor].mean() > 0.95
    rel = np.abs(out[on_floor] - truth[on_floor]) / truth[on_floor]
    assert np.median(rel) < 1e-3 and np.percentile(rel, 95) < 0.01
    # points of the walls well above the floor are not touched
    assert (out[height > 0.2] == truth[height > 0.2]).all()
