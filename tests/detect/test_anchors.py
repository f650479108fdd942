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


def _assign_frame_by_frame(anchors, gt_boxes, matched, unmatched):
    """The assigner as it was before it was batched (frame by frame, boolean indexing): the
    reference the batched one must reproduce exactly."""
    batch, n_anchor = gt_boxes.shape[0], anchors.shape[0]
    labels = torch.full((batch, n_anchor), -1, dtype=torch.long)
    targets = anchors.new_zeros(batch, n_anchor, 7)
    weights = anchors.new_zeros(batch, n_anchor)
    for b in range(batch):
        gt = gt_boxes[b][gt_boxes[b, :, 7] > 0]
        if gt.shape[0] == 0:
            labels[b] = 0
            continue
        classes = gt[:, 7].long()
        overlap = nearest_bev_iou(anchors, gt[:, :7])
        a_max, a_arg = overlap.max(dim=1)
        g_max = overlap.max(dim=0).values
        g_max = torch.where(g_max == 0, torch.full_like(g_max, -1.0), g_max)
        forced = torch.nonzero(overlap == g_max[None, :], as_tuple=True)[0]
        lab = labels[b]
        lab[forced] = classes[a_arg[forced]]
        pos = a_max >= matched
        lab[pos] = classes[a_arg[pos]]
        fg = lab > 0
        lab[a_max < unmatched] = 0
        lab[forced] = classes[a_arg[forced]]
        targets[b, fg] = encode_boxes(gt[a_arg[fg], :7], anchors[fg])
        weights[b, fg] = 1.0
    return labels, targets, weights


def _random_scenes(seed: int, batch: int = 6, m: int = 9):
    """Doors near the default grid's anchors (exact, shifted, rotated by 0/90 degrees and in
    between), boxes far outside, a second class, padding between boxes (an unknown class
    collates to 0) and a last frame without boxes: (anchors, gt (batch, m, 8))."""
    g = torch.Generator().manual_seed(seed)
    anchors = generate_anchors(ModelConfig())
    gt = torch.zeros(batch, m, 8)
    for b in range(batch - 1):  # the last frame stays empty
        n = int(torch.randint(1, m + 1, (1,), generator=g))
        pick = anchors[torch.randint(0, len(anchors), (n,), generator=g)]
        boxes = pick.clone()
        boxes[:, :2] += (torch.rand(n, 2, generator=g) - 0.5) * 0.4
        boxes[:, 3:6] *= 0.7 + 0.6 * torch.rand(n, 3, generator=g)
        boxes[:, 6] = torch.tensor([0.0, math.pi / 2, 0.3, -1.2])[
            torch.randint(0, 4, (n,), generator=g)]
        boxes[0] = pick[0]  # one exact match per frame: forced and positive at once
        if n > 2:
            boxes[1, :2] = torch.tensor([50.0, 50.0])  # overlaps no anchor: forces nothing
        gt[b, :n, :7] = boxes
        gt[b, :n, 7] = torch.randint(1, 3, (n,), generator=g).float()
        if n > 3:
            gt[b, 2, 7] = 0  # an unknown class between known ones
    return anchors, gt


@pytest.mark.parametrize("seed", range(6))
def test_batched_assignment_equals_frame_by_frame(seed):
    """Random scenes on the default anchor grid (:func:`_random_scenes`): identical labels,
    bit-identical targets and weights."""
    anchors, gt = _random_scenes(seed)
    batch = gt.shape[0]
    for thresholds in ((0.5, 0.35), (0.6, 0.45)):
        want = _assign_frame_by_frame(anchors, gt, *thresholds)
        got = assign_targets(anchors, gt, *thresholds)
        assert torch.equal(got[0], want[0])
        assert torch.equal(got[1], want[1]) and torch.equal(got[2], want[2])
        assert (got[0] > 0).sum() >= batch - 1  # every frame with a box has a positive


@pytest.mark.gpu
@pytest.mark.parametrize("seed", range(3))
def test_assignment_on_cuda_equals_the_host(seed):
    """The same scenes assigned on the GPU: the same labels and weights (the IoU thresholds and
    the forced matches pick the same anchors) and the same regression targets to float32
    rounding of the device's transcendental functions (log, atan2)."""
    anchors, gt = _random_scenes(seed)
    for thresholds in ((0.5, 0.35), (0.6, 0.45)):
        want = assign_targets(anchors, gt, *thresholds)
        got = [t.cpu() for t in assign_targets(anchors.cuda(), gt.cuda(), *thresholds)]
        assert torch.equal(got[0], want[0]) and torch.equal(got[2], want[2])
        torch.testing.assert_close(got[1], want[1], rtol=0, atol=1e-6)
