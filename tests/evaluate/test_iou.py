"""Rotated IoU against an independent polygon computation (shapely)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from shapely.geometry import Polygon

from sim2radar.evaluate import iou as iou_mod
from sim2radar.evaluate.iou import bev_iou, bev_overlaps, box_corners_bev, iou_3d


def _poly(box: np.ndarray) -> Polygon:
    x, y, _, dx, dy, _, h = box
    c, s = np.cos(h), np.sin(h)
    local = np.array([[dx, dy], [-dx, dy], [-dx, -dy], [dx, -dy]]) / 2
    return Polygon(local @ np.array([[c, s], [-s, c]]) + [x, y])


def _shapely_ious(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    bev = np.zeros((len(a), len(b)))
    d3 = np.zeros((len(a), len(b)))
    for i, ba in enumerate(a):
        for j, bb in enumerate(b):
            pa, pb = _poly(ba), _poly(bb)
            inter = pa.intersection(pb).area
            bev[i, j] = inter / (pa.area + pb.area - inter)
            h = max(0.0, min(ba[2] + ba[5] / 2, bb[2] + bb[5] / 2)
                    - max(ba[2] - ba[5] / 2, bb[2] - bb[5] / 2))
            v = inter * h
            d3[i, j] = v / (np.prod(ba[3:6]) + np.prod(bb[3:6]) - v)
    return bev, d3


def _random_boxes(rng: np.random.Generator, n: int) -> np.ndarray:
    xyz = rng.uniform([-1.5, -1.5, -0.5], [1.5, 1.5, 0.5], size=(n, 3))
    size = rng.uniform([0.1, 0.1, 0.5], [2.0, 2.0, 2.5], size=(n, 3))
    heading = rng.uniform(-np.pi, np.pi, size=(n, 1))
    return np.hstack([xyz, size, heading])


def test_random_boxes_match_shapely():
    rng = np.random.default_rng(0)
    a, b = _random_boxes(rng, 40), _random_boxes(rng, 35)
    ref_bev, ref_3d = _shapely_ious(a, b)
    assert (ref_bev > 0).mean() > 0.3  # the sample really exercises overlaps
    np.testing.assert_allclose(bev_iou(a, b), ref_bev, atol=1e-6)
    np.testing.assert_allclose(iou_3d(a, b), ref_3d, atol=1e-6)


def test_door_like_thin_boxes_and_special_cases():
    rng = np.random.default_rng(1)
    base = np.array([2.0, 0.5, 0.0, 0.95, 0.15, 2.05, 0.3])
    # near-duplicates, identical, 90-degree rotated, shared edges, tiny offsets
    boxes = [base, base + [0.02, -0.01, 0.0, 0.0, 0.0, 0.0, 0.01], base.copy(),
             base + [0, 0, 0, 0, 0, 0, np.pi / 2], base + [0, 0, 0, 0, 0, 0, np.pi],
             base + [0.95 * np.cos(0.3), 0.95 * np.sin(0.3), 0, 0, 0, 0, 0]]
    boxes += list(base + rng.normal(0, [0.05, 0.05, 0.05, 0.05, 0.02, 0.05, 0.2], (20, 7)))
    boxes = np.array(boxes)
    boxes[:, 3:6] = np.abs(boxes[:, 3:6])
    ref_bev, ref_3d = _shapely_ious(boxes, boxes)
    np.testing.assert_allclose(bev_iou(boxes, boxes), ref_bev, atol=1e-6)
    np.testing.assert_allclose(iou_3d(boxes, boxes), ref_3d, atol=1e-6)
    np.testing.assert_allclose(np.diag(iou_3d(boxes, boxes)), 1.0, atol=1e-9)
    # a box and itself rotated by pi are the same rectangle
    assert iou_3d(boxes[:1], boxes[4:5])[0, 0] == pytest.approx(1.0, abs=1e-9)
    # edge-adjacent boxes do not overlap
    assert bev_iou(boxes[:1], boxes[5:6])[0, 0] == pytest.approx(0.0, abs=1e-9)


def test_overlaps_are_positive_ious_for_every_pair(monkeypatch):
    """bev_overlaps (separating axes) says what bev_iou > 0 says, pair by pair: random boxes,
    door-like boxes side by side at gaps from -1 mm to +1 mm (touching within the band goes to
    the polygon clip), identical, rotated and nested boxes."""
    rng = np.random.default_rng(7)
    a, b = _random_boxes(rng, 60), _random_boxes(rng, 50)
    got = bev_overlaps(a, b)
    assert np.array_equal(got, bev_iou(a, b) > 0) and 0.2 < got.mean() < 0.8
    door = np.array([2.0, 0.5, 0.0, 0.95, 0.15, 2.05, 0.3])
    along = np.array([np.cos(0.3), np.sin(0.3), 0, 0, 0, 0, 0])
    across = np.array([-np.sin(0.3), np.cos(0.3), 0, 0, 0, 0, 0])
    gaps = np.array([-1e-3, -2e-4, -1e-5, -1e-8, 0.0, 1e-8, 1e-5, 2e-4, 1e-3])
    others = np.concatenate([door + (0.95 + gaps)[:, None] * along,        # end to end
                             door + (0.15 + gaps)[:, None] * across,       # side by side
                             [door, door + [0, 0, 0, 0, 0, 0, np.pi],      # itself, turned
                              door + [0, 0, 0, 0, 0, 0, np.pi / 2],       # crossed
                              door * [1, 1, 1, 0.5, 0.5, 1, 1]]])         # inside it
    clip = bev_iou(door[None], others)[0] > 0
    calls = []
    real = iou_mod.bev_iou
    monkeypatch.setattr(iou_mod, "bev_iou", lambda x, y: calls.append(1) or real(x, y))
    assert np.array_equal(bev_overlaps(door[None], others)[0], clip)
    assert clip[:2].all() and not clip[7:9].any() and clip[-4:].all()   # clear in and out
    assert 0 < len(calls) <= 10       # only the pairs within the band asked the polygon clip
    assert bev_overlaps(a[:0], b).shape == (0, 50) and bev_overlaps(a, b[:0]).shape == (60, 0)


def test_torch_float32_path_and_empty_inputs():
    rng = np.random.default_rng(2)
    a, b = _random_boxes(rng, 12), _random_boxes(rng, 9)
    out = bev_iou(torch.tensor(a, dtype=torch.float32), torch.tensor(b, dtype=torch.float32))
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
    np.testing.assert_allclose(out.numpy(), _shapely_ious(a, b)[0], atol=1e-4)
    assert bev_iou(np.zeros((0, 7)), b).shape == (0, 9)
    assert iou_3d(a, np.zeros((0, 7))).shape == (12, 0)
    with pytest.raises(ValueError, match=r"\(N, 7\)"):
        bev_iou(np.zeros((3, 5)), b)


def test_corners_are_counter_clockwise_and_sized():
    box = torch.tensor([[1.0, 2.0, 0.0, 2.0, 1.0, 1.0, np.pi / 2]])
    c = box_corners_bev(box)[0].numpy()
    np.testing.assert_allclose(c[0], [0.5, 3.0], atol=1e-6)  # front-left after 90 deg turn
    area = 0.5 * sum(c[i, 0] * c[(i + 1) % 4, 1] - c[(i + 1) % 4, 0] * c[i, 1] for i in range(4))
    assert area == pytest.approx(2.0, rel=1e-6)  # positive: counter-clockwise
