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


def _pillars(n_frames: int, points_per_frame: int, seed: int):
    from sim2radar.detect.voxelize import voxelize

    frames = make_door_frames(n_frames, seed=seed, points_per_frame=points_per_frame)
    pts, _ = collate([f.points for f in frames], [f.boxes for f in frames],
                     [f.names for f in frames], ("door",))
    c = PointPillars().cfg
    return voxelize(pts, n_frames, c.point_cloud_range_m, c.voxel_size_m,
                    c.max_points_per_voxel, c.max_voxels_train)


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda", marks=pytest.mark.gpu)])
@pytest.mark.parametrize("crowded", [False, True])
def test_pillar_net_on_real_points_matches_the_padded_net(crowded, device):
    """The one-layer PFN run on the pillars' real points (padded rows counted analytically)
    equals OpenPCDet's run over all P * 32 slots, computed in float64: outputs, gradients,
    running statistics and eval-mode outputs. ``crowded`` stacks every point into a few
    pillars so some have all 32 slots real (no padded slot joins their max). On ``cuda`` the
    real-point path (its scatter-max on the GPU) is checked against the float64 padded net on
    the CPU."""
    import copy

    pil = _pillars(3, 2500, seed=4)
    voxels, num_points, coords = pil.voxels, pil.num_points, pil.coords
    if crowded:  # 40 pillars, each with all 32 slots taken by copies of its points
        keep = torch.arange(40)
        voxels = voxels[keep][:, :1].expand(-1, 32, -1).clone()
        voxels[..., :3] += 0.01 * torch.rand_like(voxels[..., :3])
        num_points, coords = torch.full((40,), 32), coords[keep]
        num_points[::3] = 5  # a mix of full and padded pillars
        voxels[::3, 5:] = 0
    torch.manual_seed(1)
    sparse = PointPillars().vfe.train()
    with torch.no_grad():
        sparse.pfn_layers[0].norm.weight.uniform_(0.5, 1.5)
        sparse.pfn_layers[0].norm.bias.uniform_(-0.5, 0.5)
    dense = copy.deepcopy(sparse).double()
    dense.dense_pfn = True
    assert (num_points >= 32).any() == crowded

    sparse.to(device)
    on = [t.to(device) for t in (voxels, num_points, coords)]
    out = sparse(*on)
    ref = dense(voxels.double(), num_points, coords)
    torch.testing.assert_close(out.double().cpu(), ref, rtol=1e-5, atol=1e-5)
    weight = torch.randn(ref.shape, dtype=torch.float64)
    (out * weight.float().to(device)).sum().backward()
    (ref * weight).sum().backward()
    for (name, p), q in zip(sparse.named_parameters(), dense.parameters(), strict=True):
        torch.testing.assert_close(p.grad.double().cpu(), q.grad, rtol=1e-4,
                                   atol=1e-4 * q.grad.abs().max().item(), msg=name)
    for (name, b), c in zip(sparse.named_buffers(), dense.buffers(), strict=True):
        torch.testing.assert_close(b.double().cpu(), c.double(), rtol=1e-5, atol=1e-6, msg=name)
    assert sparse.pfn_layers[0].norm.num_batches_tracked.item() == 1
    sparse.eval(), dense.eval()
    torch.testing.assert_close(sparse(*on).double().cpu(),
                               dense(voxels.double(), num_points, coords), rtol=1e-5, atol=1e-5)


def test_pillar_net_product_stays_float32_under_bfloat16_autocast():
    """Under CPU bfloat16 autocast the pillar net's linear layer runs in float32 (a new row
    count every step: oneDNN's bfloat16 matmul kept state per count, ~1 MB each); its output
    is the float32 net's, rounded once to bfloat16 for the canvas."""
    pil = _pillars(2, 2000, seed=5)
    torch.manual_seed(2)
    vfe = PointPillars().vfe.eval()
    args = (pil.voxels, pil.num_points, pil.coords)
    with torch.no_grad():
        want = vfe(*args)
        with torch.autocast("cpu", dtype=torch.bfloat16):
            got = vfe(*args)
    assert got.dtype == torch.bfloat16 and want.dtype == torch.float32
    assert torch.equal(got, want.to(torch.bfloat16))


def test_detection_head_runs_its_three_convolutions_as_one():
    """The head stacks conv_cls / conv_box / conv_dir_cls (OpenPCDet's names, kept in the state
    dict) into one 1x1 convolution: each output equals its own convolution's."""
    torch.manual_seed(0)
    head = PointPillars().dense_head
    x = torch.randn(2, head.conv_cls.in_channels, 6, 5)
    out = head(x)

    def flat(t, k):
        return t.permute(0, 2, 3, 1).reshape(2, -1, k)

    torch.testing.assert_close(out["cls_preds"], flat(head.conv_cls(x), 1))
    torch.testing.assert_close(out["box_preds"], flat(head.conv_box(x), 7))
    torch.testing.assert_close(out["dir_preds"], flat(head.conv_dir_cls(x), 2))
    names = set(PointPillars().state_dict())
    assert {"dense_head.conv_cls.weight", "dense_head.conv_dir_cls.bias",
            "backbone_2d.blocks.0.1.weight", "backbone_2d.blocks.0.2.running_var"} <= names


def test_a_batch_without_pillars_is_refused_in_training_and_empty_in_eval():
    """No point inside the range: training refuses the batch (BatchNorm statistics of zero
    rows would be NaN and poison the running statistics); evaluation gives no features."""
    vfe = PointPillars().vfe
    empty = (torch.zeros(0, 32, 4), torch.zeros(0, dtype=torch.long),
             torch.zeros(0, 4, dtype=torch.long))
    before = vfe.pfn_layers[0].norm.running_mean.clone()
    with pytest.raises(ValueError, match="point_cloud_range_m"):
        vfe.train()(*empty)
    torch.testing.assert_close(vfe.pfn_layers[0].norm.running_mean, before)
    assert vfe.eval()(*empty).shape == (0, 64)
