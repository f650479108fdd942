"""Multi-view fusion of reconstructed scenes (sim2radar/reconstruct/fusion.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.camera import CameraIntrinsics
from sim2radar.mesh import box_mesh
from sim2radar.reconstruct.fusion import EarlierView, FusionConfig, fuse_views

#: OpenCV camera (x right, y down, z forward) -> target frame (x forward, y left, z up)
CAMERA_TO_TARGET = np.array([[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0],
                             [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
K = CameraIntrinsics.from_fov(160, 120, 66.0)


def _wall_at(azimuth_deg: float, range_m: float, name: str):
    a = math.radians(azimuth_deg)
    return box_mesh([range_m * math.cos(a), range_m * math.sin(a), 0.0], [0.05, 0.6, 1.0],
                    a, material="concrete", name=name)


def test_earlier_views_add_only_what_the_current_camera_does_not_see():
    current = [_wall_at(0.0, 4.0, "ahead")]
    # an earlier view 2 m behind: it saw a wall straight ahead (inside the current image) and
    # one at 65 deg of the *current* frame (outside the camera's +-33 deg)
    back = np.eye(4)
    back[0, 3] = -2.0                                   # earlier frame -> current frame
    to_view = np.linalg.inv(back)
    seen_now = _wall_at(0.0, 4.0, "ahead_again").transformed(to_view)
    side = _wall_at(65.0, 2.5, "side").transformed(to_view)
    boxes_now = np.array([[4.0, 0.0, 0.0, 0.9, 0.17, 2.0, math.pi / 2]], np.float32)
    side_box = np.array([[1.0, 2.3, 0.0, 0.9, 0.17, 2.0, 0.3]], np.float32)   # current frame
    view = EarlierView([seen_now, side], np.concatenate([
        np.array([[6.0, 0.0, 0.0, 0.9, 0.17, 2.0, math.pi / 2]], np.float32),  # = boxes_now
        side_box + np.array([2.0, 0, 0, 0, 0, 0, 0], np.float32)]), back)
    fused = fuse_views(current, boxes_now, [view], K, CAMERA_TO_TARGET)
    names = [m.name for m in fused.meshes]
    assert names == ["ahead", "side_earlier1"]
    assert fused.triangles_added == len(side.faces)
    np.testing.assert_allclose(fused.meshes[1].vertices, _wall_at(65.0, 2.5, "s").vertices,
                               atol=1e-5)
    assert fused.views == 1 and fused.boxes_added == 1
    assert len(fused.door_boxes) == 2
    assert fused.door_boxes[1] == pytest.approx(side_box[0], abs=1e-5)


def test_no_earlier_view_is_the_current_scene():
    current = [_wall_at(10.0, 3.0, "w")]
    boxes = np.zeros((0, 7), np.float32)
    fused = fuse_views(current, boxes, [], K, CAMERA_TO_TARGET)
    assert [m.name for m in fused.meshes] == ["w"] and fused.triangles_added == 0
    assert fused.door_boxes.shape == (0, 7)
    with pytest.raises(ValueError, match="frames"):
        FusionConfig(frames=-1)
