"""Training augmentation keeps labels consistent with points."""

from __future__ import annotations

import numpy as np

from sim2radar.datasets import make_door_frames
from sim2radar.detect.augment import (
    augment_frame,
    boxes_in_range,
    build_gt_database,
    global_rotation,
    global_scaling,
    points_in_boxes,
    random_flip_x,
    sample_ground_truth,
)
from sim2radar.detect.config import AugmentConfig, ModelConfig
from sim2radar.evaluate import bev_iou


def _membership(points, boxes):
    return points_in_boxes(points, boxes)


def test_geometric_transforms_keep_points_inside_their_boxes():
    f = make_door_frames(1, seed=3)[0]
    before = _membership(f.points, f.boxes)
    assert before.sum() > 50
    rng = np.random.default_rng(0)
    for _ in range(4):
        p, b = random_flip_x(f.points, f.boxes, rng)
        p, b = global_rotation(p, b, (-0.785, 0.785), rng)
        p, b = global_scaling(p, b, (0.95, 1.05), rng)
        after = _membership(p, b)
        # boundary points may flip by float rounding; the rest must not change
        assert (after != before).sum() <= 2
    flipped, fb = random_flip_x(f.points, f.boxes, np.random.default_rng(1))
    if not np.array_equal(flipped, f.points):
        np.testing.assert_allclose(fb[:, 6], -f.boxes[:, 6])


def test_gt_sampling_adds_non_overlapping_doors_with_their_points():
    frames = make_door_frames(12, seed=4)
    db = build_gt_database(frames[1:], ("door",), min_points=5)
    assert len(db) >= 12
    f = frames[0]
    rng = np.random.default_rng(0)
    pts, boxes, names = sample_ground_truth(f.points, f.boxes, f.names, db, {"door": 6}, rng)
    assert len(f.boxes) < len(boxes) <= 6 and names == ("door",) * len(boxes)
    iou = bev_iou(boxes.astype(np.float64), boxes.astype(np.float64))
    np.fill_diagonal(iou, 0)
    assert iou.max() == 0  # no two boxes overlap
    inside = points_in_boxes(pts, boxes[len(f.boxes):])
    assert (inside.sum(axis=0) >= 5).all()  # every pasted door brought its points


def test_augment_frame_is_reproducible_and_keeps_boxes_in_range():
    f = make_door_frames(1, seed=5)[0]
    db = build_gt_database(make_door_frames(6, seed=6), ("door",))
    cfg = AugmentConfig()
    r = ModelConfig().point_cloud_range_m
    a = augment_frame(f, cfg, np.random.default_rng(7), r, db)
    b = augment_frame(f, cfg, np.random.default_rng(7), r, db)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])
    assert boxes_in_range(a[1], r).all()
    assert a[0].dtype == np.float32 and a[0].shape[1] == 4
