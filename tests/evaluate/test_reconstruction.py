"""Reconstruction scores: depth, segmentation, materials, door boxes, radar point clouds."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim2radar.evaluate.reconstruction import (
    aggregate_scores,
    box_iou_3d,
    chamfer_distance,
    depth_metrics,
    match_boxes,
    material_counts,
    score_reconstruction,
    segmentation_counts,
)
from sim2radar.reconstruct import FrameInput, ReconstructionConfig, reconstruct
from sim2radar.reconstruct.synthetic import corridor_frame


def test_depth_metrics_known_values():
    gt = np.full((4, 5), 2.0)
    pred = gt.copy()
    pred[0] = 2.2        # +10 % on 5 of 20 pixels
    pred[1, :2] = 3.0    # +50 % on 2 pixels (δ fails)
    pred[2, 0] = 0       # missing
    gt[3, 0] = 0         # no ground truth
    m = depth_metrics(pred, gt)
    assert m["n_px"] == 18
    assert m["abs_rel"] == pytest.approx((5 * 0.1 + 2 * 0.5) / 18)
    assert m["delta_1_25"] == pytest.approx(16 / 18)
    assert m["coverage"] == pytest.approx(18 / 19)
    assert math.isnan(depth_metrics(np.zeros((2, 2)), np.ones((2, 2)))["abs_rel"])
    with pytest.raises(ValueError):
        depth_metrics(np.ones((2, 2)), np.ones((2, 3)))


def test_segmentation_iou_and_material_accuracy():
    gt = np.array([[1, 1, 2, 2], [1, 1, 2, 4], [0, 0, 0, 0]])
    pred = np.array([[1, 1, 1, 2], [1, 1, 2, 2], [4, 4, 4, 4]])
    c = segmentation_counts(pred, gt)
    iou = c.iou()
    assert iou["wall"] == pytest.approx(4 / 5)
    assert iou["floor"] == pytest.approx(2 / 4)
    assert iou["door"] == 0.0
    assert c.miou() == pytest.approx((0.8 + 0.5 + 0) / 3)
    assert (c + c).miou() == pytest.approx(c.miou())
    mc = material_counts(pred, gt)
    assert mc.accuracy() == pytest.approx(6 / 8)
    assert mc.per_class()["metal"] == pytest.approx(1.0)     # id 1: 4/4
    assert mc.per_class()["glass"] == pytest.approx(2 / 3)   # id 2
    assert mc.per_class()["plasterboard"] == 0.0             # id 4


def test_box_iou_3d():
    a = np.array([[0, 0, 0, 2, 1, 2, 0]], float)
    assert box_iou_3d(a, a)[0, 0] == pytest.approx(1)
    shifted = a.copy()
    shifted[0, 0] = 1.0  # half overlap along x
    assert box_iou_3d(a, shifted)[0, 0] == pytest.approx(1 / 3)
    turned = a.copy()
    turned[0, 6] = math.pi / 2  # 2x1 footprint turned by 90 deg: overlap 1x1
    assert box_iou_3d(a, turned)[0, 0] == pytest.approx(1 / 3)
    flipped = a.copy()
    flipped[0, 6] = math.pi
    assert box_iou_3d(a, flipped)[0, 0] == pytest.approx(1)
    lifted = a.copy()
    lifted[0, 2] = 1.5  # z overlap 0.5 of 2
    assert box_iou_3d(a, lifted)[0, 0] == pytest.approx(0.25 / 1.75)
    assert box_iou_3d(a, np.zeros((0, 7))).shape == (1, 0)


def test_matching_is_one_to_one():
    gt = np.array([[0, 0, 0, 1, 0.2, 2, 0], [3, 0, 0, 1, 0.2, 2, 0]], float)
    pred = np.array([[0.05, 0, 0, 1, 0.2, 2, 0], [0.1, 0, 0, 1, 0.2, 2, 0], [9, 9, 0, 1, 1, 1, 0]])
    m = match_boxes(pred, gt, 0.3)
    assert m["tp"] == 1 and m["recall"] == 0.5 and m["precision"] == pytest.approx(1 / 3)
    assert m["ious"][0] > 0.85 and m["ious"][1] == 0
    empty = match_boxes(np.zeros((0, 7)), gt)
    assert empty["recall"] == 0 and math.isnan(empty["precision"])


def test_chamfer_distance():
    a = np.random.default_rng(0).uniform(0, 5, (200, 4))
    assert chamfer_distance(a, a) == 0
    b = a.copy()
    b[:, 0] += 0.1
    assert chamfer_distance(a, b) == pytest.approx(0.1, abs=0.02)
    assert math.isnan(chamfer_distance(a, np.zeros((0, 3))))


def test_score_and_aggregate_on_oracle_frames():
    scores = []
    for seed in (1, 2):
        f = corridor_frame(96, 72, seed=seed)
        scene = reconstruct(FrameInput(f.rgb, f.intrinsics, f.lidar_points),
                            ReconstructionConfig.preset("oracle"), ground_truth=f)
        pts = np.random.default_rng(seed).uniform(0, 5, (50, 4))
        scores.append(score_reconstruction(scene, f, radar_points=pts, radar_points_gt=pts[:25]))
    agg = aggregate_scores(scores)
    s = agg.summary()
    assert s["abs_rel"] == 0 and s["miou"] == 1 and s["material_acc"] == 1
    assert s["radar_points_ratio"] == pytest.approx(2.0)
    assert agg.doors["n_gt"] == sum(x.doors["n_gt"] for x in scores)
    with pytest.raises(ValueError):
        aggregate_scores([])
