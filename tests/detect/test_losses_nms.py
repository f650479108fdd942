"""Loss terms and rotated NMS."""

from __future__ import annotations

import math

import pytest
import torch

from sim2radar.detect.losses import (
    add_sin_difference,
    direction_targets,
    sigmoid_focal_loss,
    weighted_smooth_l1,
)
from sim2radar.detect.nms import rotated_nms
from sim2radar.hardware import has_cuda


def test_focal_loss_matches_formula():
    logits = torch.tensor([2.0, -1.0, 0.5])
    targets = torch.tensor([1.0, 0.0, 0.0])
    p = torch.sigmoid(logits)
    expected = torch.stack([
        -0.25 * (1 - p[0]) ** 2 * torch.log(p[0]),
        -0.75 * p[1] ** 2 * torch.log(1 - p[1]),
        -0.75 * p[2] ** 2 * torch.log(1 - p[2]),
    ])
    torch.testing.assert_close(sigmoid_focal_loss(logits, targets), expected)


def test_sin_difference_makes_heading_error_periodic():
    p = torch.tensor([[0, 0, 0, 0, 0, 0, math.pi + 0.1]])
    t = torch.tensor([[0, 0, 0, 0, 0, 0, 0.1]])
    ps, ts = add_sin_difference(p, t)
    # sin(a)cos(b) - cos(a)sin(b) = sin(a - b) = sin(pi) = 0: a half-turn costs nothing
    assert (ps - ts)[0, 6].item() == pytest.approx(0.0, abs=1e-6)
    w = torch.ones(7)
    assert weighted_smooth_l1(ps, ts, 1 / 9, w).sum().item() == pytest.approx(0.0, abs=1e-6)
    # smooth-L1: quadratic below beta, linear above
    d = weighted_smooth_l1(torch.tensor([0.05, 1.0]), torch.zeros(2), 1 / 9, torch.ones(2))
    torch.testing.assert_close(d, torch.tensor([0.5 * 0.05**2 * 9, 1.0 - 0.5 / 9]))


def test_direction_targets_split_headings_into_half_turns():
    anchors = torch.zeros(4, 7)
    targets = torch.zeros(4, 7)
    targets[:, 6] = torch.tensor([0.0, 1.0, math.pi, -2.0])
    # bins by (heading - pi/4) mod 2pi: [pi/4, 5pi/4) -> 0, else 1
    assert direction_targets(anchors, targets, 0.78539, 2).tolist() == [1, 0, 0, 1]


def _boxes(device="cpu"):
    return torch.tensor([
        [2.0, 1.0, 0.0, 0.95, 0.2, 2.05, 0.0],
        [2.02, 1.01, 0.0, 0.95, 0.2, 2.05, 0.02],   # duplicate of 0
        [2.0, 1.0, 0.0, 0.95, 0.2, 2.05, math.pi / 2],  # crossing 0: overlaps
        [4.0, -2.0, 0.0, 0.95, 0.2, 2.05, 0.3],     # separate
        [2.94, 1.0, 0.0, 0.95, 0.2, 2.05, 0.0],     # touches 0 slightly (IoU 0.005)
    ], device=device)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)])
def test_rotated_nms(device):
    if device == "cuda" and not has_cuda():
        pytest.skip("needs a CUDA GPU")
    boxes = _boxes(device)
    scores = torch.tensor([0.9, 0.8, 0.7, 0.6, 0.5], device=device)
    keep = rotated_nms(boxes, scores, 0.01)
    assert keep.cpu().tolist() == [0, 3, 4]
    assert rotated_nms(boxes, scores, 0.01, post_max=2).cpu().tolist() == [0, 3]
    assert rotated_nms(boxes, scores, 0.01, pre_max=2).cpu().tolist() == [0]
    # scores decide who survives
    scores2 = torch.tensor([0.1, 0.8, 0.95, 0.6, 0.5], device=device)
    assert rotated_nms(boxes, scores2, 0.01).cpu().tolist() == [2, 3, 4]
    assert rotated_nms(boxes[:0], scores[:0], 0.01).numel() == 0
