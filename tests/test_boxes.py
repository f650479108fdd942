"""Tests for sim2radar/boxes.py."""

import math

import numpy as np
import pytest

from sim2radar.boxes import (
    box_corners,
    boxes_in_view,
    boxes_to_frame,
    points_in_boxes,
    transform_boxes,
    wrap_heading,
)
from sim2radar.mesh import box_mesh


def _pose(x, y, z, yaw):
    m = np.eye(4)
    m[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    m[:3, 3] = [x, y, z]
    return m


def test_corners_match_the_box_mesh_and_contain_only_interior_points():
    box = np.array([1.0, 2.0, 1.0, 0.9, 0.2, 2.0, 0.4])
    corners = box_corners(box)[0]
    mesh = box_mesh(box[:3], box[3:6], box[6], material="metal")
    np.testing.assert_allclose(np.sort(corners, axis=0), np.sort(mesh.vertices, axis=0), atol=1e-6)
    inside = points_in_boxes(np.vstack([box[:3], box[:3] + 0.999 * (corners - box[:3])]), box)
    assert inside.all()
    grown = points_in_boxes(box[None, :3] + [[0, 0, 1.05]], box, margin_m=0.1)
    assert grown[0, 0] and not points_in_boxes(box[None, :3] + [[0, 0, 1.05]], box)[0, 0]


def test_moving_boxes_and_points_together_keeps_membership():
    rng = np.random.default_rng(0)
    boxes = np.column_stack([rng.uniform(-3, 3, (5, 3)), rng.uniform(0.2, 2, (5, 3)),
                             rng.uniform(-3, 3, 5)])
    pts = rng.uniform(-4, 4, (400, 3))
    pose = _pose(1.5, -2.0, 0.3, 0.7)
    moved_pts = pts @ pose[:3, :3].T + pose[:3, 3]
    moved = transform_boxes(boxes, pose)
    np.testing.assert_array_equal(points_in_boxes(pts, boxes), points_in_boxes(moved_pts, moved))
    back = boxes_to_frame(moved, pose)
    np.testing.assert_allclose(back[:, :6], boxes[:, :6], atol=1e-5)
    np.testing.assert_allclose(np.cos(2 * back[:, 6]), np.cos(2 * boxes[:, 6]), atol=1e-5)


def test_wrap_and_view():
    assert wrap_heading(np.array([math.pi / 2]))[0] == pytest.approx(-math.pi / 2)
    assert wrap_heading(np.array([3 * math.pi / 2]), "full")[0] == pytest.approx(-math.pi / 2)
    boxes = np.array([[3, 0, 0, 1, 1, 1, 0], [3, 6, 0, 1, 1, 1, 0], [-3, 0, 0, 1, 1, 1, 0],
                      [12, 0, 0, 1, 1, 1, 0]], float)
    np.testing.assert_array_equal(boxes_in_view(boxes, 120, 40, 9.7), [True, False, False, False])
