"""The paper's PointPillars: shapes, OpenPCDet hyper-parameters, one training step."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sim2radar.datasets import make_door_frames
from sim2radar.detect import PointPillars
from sim2radar.detect.model import ENCODER_MODULES
from sim2radar.detect.train import collate


def test_default_model_is_the_papers():
    m = PointPillars()
    cfg = m.cfg
    assert cfg.class_names == ("door",) and len(cfg.anchor.rotations_rad) == 2
    assert cfg.grid_size[:2] == (128, 208)
    pfn = m.vfe.pfn_layers[0]
    assert pfn.linear.in_features == 10 and pfn.linear.out_features == 64
    assert pfn.linear.bias is None
    assert pfn.norm.eps == 1e-3 and pfn.norm.momentum == 0.01
    convs = [[mod for mod in blk if isinstance(mod, torch.nn.Conv2d)] for blk in m.backbone_2d.blocks]
    assert [len(c) - 1 for c in convs] == [3, 5, 5]
    assert [c[0].stride[0] for c in convs] == [2, 2, 2]
    assert [c[0].out_channels for c in convs] == [64, 128, 256]
    ups = [blk[0] for blk in m.backbone_2d.deblocks]
    assert [u.stride[0] for u in ups] == [1, 2, 4] and [u.out_channels for u in ups] == [128] * 3
    assert m.dense_head.conv_cls.out_channels == 2  # 2 rotations x 1 class
    assert m.dense_head.conv_box.out_channels == 14
    assert m.dense_head.conv_dir_cls.out_channels == 4
    assert m.anchors.shape[0] == 104 * 64 * 2
    assert 4.5e6 < sum(p.numel() for p in m.parameters()) < 5.0e6  # OpenPCDet: ~4.8 M


def test_full_default_model_forward_backward_on_a_tiny_batch():
    torch.manual_seed(0)
    frames = make_door_frames(2, seed=0, points_per_frame=600)
    pts, gt = collate([f.points for f in frames], [f.boxes for f in frames],
                      [f.names for f in frames], ("door",))
    m = PointPillars().train()
    out = m(pts, 2)
    a = m.anchors.shape[0]
    assert out["cls_preds"].shape == (2, a, 1)
    assert out["box_preds"].shape == (2, a, 7) and out["dir_preds"].shape == (2, a, 2)
    loss, parts = m.loss(out, gt)
    assert np.isfinite(parts["total"]) and parts["loc"] > 0 and parts["cls"] > 0
    loss.backward()
    grads = {n: p.grad for n, p in m.named_parameters()}
    assert all(g is not None and torch.isfinite(g).all() for g in grads.values())
    # the initial class prior pi = 0.01: mean score ~0.01 before training
    m.eval()
    with torch.no_grad():
        boxes, scores = m.decode(m(pts, 2))
    assert boxes.shape == (2, a, 7)
    assert scores.mean().item() == pytest.approx(0.01, abs=0.01)


def test_scatter_puts_pillar_features_in_their_cell():
    m = PointPillars()
    feats = torch.arange(2 * 64, dtype=torch.float32).view(2, 64)
    coords = torch.tensor([[0, 0, 5, 7], [1, 0, 207, 127]])
    canvas = m.map_to_bev(feats, coords, 2)
    assert canvas.shape == (2, 64, 208, 128)
    torch.testing.assert_close(canvas[0, :, 5, 7], feats[0])
    torch.testing.assert_close(canvas[1, :, 207, 127], feats[1])
    assert canvas.abs().sum().item() == pytest.approx(feats.sum().item())


def test_point_feature_count_is_checked():
    m = PointPillars()
    with pytest.raises(ValueError, match="num_point_features"):
        m(torch.zeros(10, 4), 1)  # batch index + x y z: intensity missing


def test_encoder_split_and_shape_check():
    m = PointPillars()
    enc = m.encoder_state_dict()
    assert enc and all(k.split(".")[0] in ENCODER_MODULES for k in enc)
    assert not any(k.startswith("dense_head") for k in enc)
    bad = dict(m.state_dict())
    bad["vfe.pfn_layers.0.linear.weight"] = torch.zeros(64, 11)
    with pytest.raises(ValueError, match="shapes differ"):
        PointPillars().load_encoder(bad)
