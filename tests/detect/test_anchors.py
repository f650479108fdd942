"""Anchors, residual coder and target assignment."""

from __future__ import annotations

import math

import pytest
import torch

from sim2radar.detect.anchors import (
    assign_targets,
    decode_boxes,
    encode_boxes,
    generate_anchors,
    nearest_bev_iou,
)
from sim2radar.detect.config import ModelConfig


def test_default_anchor_grid():
    cfg = ModelConfig()
    assert cfg.grid_size == (128, 208, 1)
    a = generate_anchors(cfg)
    assert a.shape == (104 * 64 * 2, 7)
    grid = a.view(104, 64, 2, 7)
    # OpenPCDet (align_center False): anchors span the range edge to edge
    assert grid[0, 0, 0, 0].item() == pytest.approx(-1.0)
    assert grid[0, -1, 0, 0].item() == pytest.approx(5.4)
    assert grid[-1, 0, 0, 1].item() == pytest.approx(5.2)
    assert grid[0, 0, 1, 6].item() == pytest.approx(math.pi / 2)
    # door bottom on the floor
    assert (grid[..., 2] - grid[..., 5] / 2).unique().item() == pytest.approx(-1.05)


def test_encode_decode_roundtrip():
    g = torch.Generator().manual_seed(0)
    anchors = torch.rand(100, 7, generator=g) + 0.2
    boxes = torch.rand(100, 7, generator=g) + 0.2
    torch.testing.assert_close(decode_boxes(encode_boxes(boxes, anchors), anchors), boxes)


def test_assignment_positive_negative_and_forced():
    anchors = torch.tensor([
        [2.0, 1.0, 0.0, 0.95, 0.2, 2.05, 0.0],        # exact match
        [2.0, 1.0, 0.0, 0.95, 0.2, 2.05, math.pi / 2],  # rotated: low IoU
        [4.0, -3.0, 0.0, 0.95, 0.2, 2.05, 0.0],         # far away
        [0.0, 3.0, 0.0, 0.95, 0.2, 2.05, 0.0],          # best (but poor) match of box 2
    ])
    gt = torch.zeros(1, 3, 8)
    gt[0, 0] = torch.tensor([2.0, 1.0, 0.0, 0.95, 0.2, 2.05, 0.0, 1])
    gt[0, 1] = torch.tensor([0.6, 3.0, 0.0, 0.95, 0.2, 2.05, 0.0, 1])  # IoU with anchor 3 < 0.35
    labels, targets, weights = assign_targets(anchors, gt, 0.5, 0.35)
    assert labels[0].tolist() == [1, 0, 0, 1]
    assert weights[0].tolist() == [1.0, 0.0, 0.0, 1.0]
    torch.testing.assert_close(targets[0, 0], torch.zeros(7))
    assert nearest_bev_iou(anchors[3:4], gt[0, 1:2, :7]).item() < 0.35
    # a frame without boxes: every anchor negative
    labels, _, _ = assign_targets(anchors, torch.zeros(1, 2, 8), 0.5, 0.35)
    assert labels.tolist() == [[0, 0, 0, 0]]


def test_nearest_bev_swaps_sizes_for_boxes_closer_to_the_y_axis():
    box = torch.tensor([[0.0, 0.0, 0.0, 2.0, 0.5, 1.0, 1.4]])  # ~80 deg: treated as 90
    same = torch.tensor([[0.0, 0.0, 0.0, 0.5, 2.0, 1.0, 0.0]])
    assert nearest_bev_iou(box, same).item() == pytest.approx(1.0)
