"""PointPillars (Lang et al., CVPR 2019) in pure PyTorch, module for module as in OpenPCDet.

Submodule names follow OpenPCDet (``vfe``, ``map_to_bev``, ``backbone_2d``, ``dense_head``), so
parameter names read the same. The *encoder* transferred from sim pre-training is
``vfe`` + ``map_to_bev`` + ``backbone_2d`` (:data:`ENCODER_MODULES`); ``dense_head`` is the head.

Shapes for the default config (B frames, P pillars, M = 32 points per pillar):

* points (N, 1 + 4): batch index, x, y, z [m], intensity
* PillarVFE: (P, 32, 10) point features -> (P, 64)
* PointPillarScatter: -> (B, 64, 208, 128) BEV canvas (y rows, x columns)
* BaseBEVBackbone: -> (B, 384, 104, 64)
* AnchorHeadSingle: per anchor (104 * 64 * 2 = 13,312): class logit, 7 box residuals,
  2 direction logits
"""

from __future__ import annotations

import contextlib
import math
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from sim2radar.detect.anchors import (
    assign_targets,
    decode_boxes,
    generate_anchors,
    limit_period,
)
from sim2radar.detect.config import ModelConfig
from sim2radar.detect.losses import (
    add_sin_difference,
    direction_targets,
    sigmoid_focal_loss,
    weighted_smooth_l1,
)
from sim2radar.detect.nms import rotated_nms
from sim2radar.detect.voxelize import voxelize

__all__ = [
    "ENCODER_MODULES",
    "AnchorHeadSingle",
    "BaseBEVBackbone",
    "Detections",
    "PFNLayer",
    "PillarVFE",
    "PointPillarScatter",
    "PointPillars",
    "seeded_model",
]

#: Submodules that make up the transferable encoder (paper §5.1).
ENCODER_MODULES: tuple[str, ...] = ("vfe", "map_to_bev", "backbone_2d")


def _bn1d(c: int, momentum: float = 0.01) -> nn.BatchNorm1d:
    return nn.BatchNorm1d(c, eps=1e-3, momentum=momentum)


def _bn2d(c: int, momentum: float = 0.01) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(c, eps=1e-3, momentum=momentum)


class PFNLayer(nn.Module):
    """Linear (no bias) -> BatchNorm1d -> ReLU -> max over points (OpenPCDet ``PFNLayer``)."""

    def __init__(
        self, in_channels: int, out_channels: int, last_layer: bool, bn_momentum: float = 0.01
    ) -> None:
        super().__init__()
        self.last_vfe = last_layer
        out = out_channels if last_layer else out_channels // 2
        self.linear = nn.Linear(in_channels, out, bias=False)
        self.norm = _bn1d(out, bn_momentum)

    def _linear(self, x: torch.Tensor) -> torch.Tensor:
        """The layer's product in float32 whatever autocast says. Its row count (the batch's
        points or pillars) is new every step, and oneDNN's bfloat16 matmul on a CPU keeps
        state per shape: a training process's resident memory grew ~1 MB per new count (0.9
        GiB over a thousand), where the convolutions' fixed shapes add nothing. The product
        is ~10 x 32 multiply-adds per row, so float32 costs nothing; its output went to float32
        for the batch statistics anyway."""
        dtype = torch.promote_types(x.dtype, torch.float32)   # (a float64 net stays float64)
        with torch.autocast(x.device.type, enabled=False):
            return F.linear(x.to(dtype), self.linear.weight.to(dtype))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(P, M, C_in) -> (P, 1, C_out) if last layer, else (P, M, C_out)."""
        p, m, _ = x.shape
        y = self.norm(self._linear(x).reshape(p * m, -1)).reshape(p, m, -1)
        y = F.relu(y)
        y_max = y.max(dim=1, keepdim=True).values
        if self.last_vfe:
            return y_max
        return torch.cat([y, y_max.expand(-1, m, -1)], dim=2)

    def forward_points(
        self, x: torch.Tensor, pillar: torch.Tensor, n_pillars: int, n_slots: int,
        full: torch.Tensor,
    ) -> torch.Tensor:
        """The last layer's (P, C_out) output from the pillars' real points only.

        :meth:`forward` runs on every one of the P * M slots, most of them padding (IFR's
        ~2,000 points per frame fill ~1.6 of a pillar's 32 slots). A padded slot's features are
        zero and the linear layer has no bias, so its pre-norm value is exactly 0: the batch
        statistics over all P * M rows and each pillar's max follow from the real rows alone,
        with the padded rows counted analytically. Same parameters, running statistics and
        (up to float rounding; statistics in float32) the same outputs and gradients as
        :meth:`forward` on the padded tensor.

        Parameters
        ----------
        x : (n, C_in) features of the real points.
        pillar : (n,) int64 — each point's pillar index in ``[0, n_pillars)``.
        n_pillars, n_slots : P and M of the padded tensor the layer stands in for.
        full : (P,) bool — pillars with all M slots real (no padded slot joins their max).
        """
        if not self.last_vfe:
            raise ValueError("forward_points is the last PFN layer's: earlier layers feed "
                             "their padded slots' (non-zero) outputs to the next layer")
        norm = self.norm
        device = x.device.type
        # autocast's dtype, which the canvas and the backbone then use
        dtype = torch.get_autocast_dtype(device) if torch.is_autocast_enabled(device) \
            else x.dtype
        y = self._linear(x)
        if norm.training:
            if n_pillars == 0:  # nn.BatchNorm1d refuses an empty batch in training alike
                raise ValueError("no point of the batch lies inside model.point_cloud_range_m: "
                                 "a training step needs at least one pillar")
            rows = n_pillars * n_slots
            mean = y.sum(dim=0) / rows
            var = ((y - mean).square().sum(dim=0) + (rows - y.shape[0]) * mean.square()) / rows
            with torch.no_grad():  # nn.BatchNorm1d's update: unbiased variance, momentum
                norm.running_mean.lerp_(mean, norm.momentum)
                norm.running_var.lerp_(var * (rows / max(rows - 1, 1)), norm.momentum)
                norm.num_batches_tracked.add_(1)
        else:
            mean, var = norm.running_mean, norm.running_var
        scale = norm.weight * torch.rsqrt(var + norm.eps)
        shift = norm.bias - mean * scale
        z = F.relu(y * scale + shift)
        index = pillar[:, None].expand_as(z)
        out = z.new_full((n_pillars, z.shape[1]), -math.inf)
        out = out.scatter_reduce(0, index, z, reduce="amax", include_self=True)
        return torch.where(full[:, None], out, torch.maximum(out, F.relu(shift))).to(dtype)


class PillarVFE(nn.Module):
    """Pillar feature net (OpenPCDet ``PillarVFE``, USE_NORM, absolute xyz, no distance).

    Per point: raw features (x, y, z, extra...), offset to the pillar's point mean (3) and offset
    to the pillar centre (3): ``C + 6`` features (10 for x, y, z, intensity). Then Linear (no
    bias) -> BatchNorm1d(eps 1e-3, momentum 0.01) -> ReLU -> max over the pillar's points.
    """

    def __init__(self, cfg: ModelConfig) -> None:
        super().__init__()
        self.num_point_features = cfg.num_point_features
        self.voxel_size_m = cfg.voxel_size_m
        self.point_cloud_range_m = cfg.point_cloud_range_m
        channels = [cfg.num_point_features + 6, *cfg.vfe_filters]
        self.pfn_layers = nn.ModuleList(
            PFNLayer(channels[i], channels[i + 1], i == len(channels) - 2, cfg.bn_momentum)
            for i in range(len(channels) - 1)
        )
        self.out_channels = channels[-1]
        #: run a one-layer PFN on every padded slot (OpenPCDet's way) instead of on the
        #: pillars' real points (:meth:`PFNLayer.forward_points`; same result, less work)
        self.dense_pfn = False

    def forward(
        self, voxels: torch.Tensor, num_points: torch.Tensor, coords: torch.Tensor
    ) -> torch.Tensor:
        """(P, M, C) pillars, (P,) counts, (P, 4) coords -> (P, out_channels) features."""
        m = voxels.shape[1]
        counts = num_points.to(voxels.dtype).clamp(min=1)
        point_mean = voxels[..., :3].sum(dim=1) / counts[:, None]  # padded slots hold zeros
        vx, vy, vz = self.voxel_size_m
        r = self.point_cloud_range_m
        centre = torch.stack(
            [coords[:, 3].to(voxels.dtype) * vx + (vx / 2 + r[0]),
             coords[:, 2].to(voxels.dtype) * vy + (vy / 2 + r[1]),
             coords[:, 1].to(voxels.dtype) * vz + (vz / 2 + r[2])],
            dim=1,
        )

        def decorated(points, mean, centre):  # raw columns, offsets to pillar mean and centre
            xyz = points[..., :3]
            return torch.cat([points, xyz - mean, xyz - centre], dim=-1)

        mask = torch.arange(m, device=voxels.device)[None, :] < num_points[:, None]
        if len(self.pfn_layers) == 1 and not self.dense_pfn:
            pillar, slot = mask.nonzero(as_tuple=True)
            features = decorated(voxels[pillar, slot], point_mean[pillar], centre[pillar])
            return self.pfn_layers[0].forward_points(
                features, pillar, voxels.shape[0], m, num_points >= m)
        features = decorated(voxels, point_mean[:, None, :], centre[:, None, :])
        features = features * mask[..., None].to(features.dtype)
        for pfn in self.pfn_layers:
            features = pfn(features)
        return features.squeeze(1)


class PointPillarScatter(nn.Module):
    """Scatter pillar features to the BEV canvas (OpenPCDet ``PointPillarScatter``).

    The canvas is built as (B, ny, nx, C) and returned as a (B, C, ny, nx) view, i.e. in
    channels-last memory layout, which the CPU convolutions of the backbone prefer.
    """

    def __init__(self, cfg: ModelConfig, num_bev_features: int) -> None:
        super().__init__()
        self.nx, self.ny, self.nz = cfg.grid_size
        self.num_bev_features = num_bev_features

    def forward(self, features: torch.Tensor, coords: torch.Tensor, batch_size: int):
        flat = (coords[:, 0] * self.ny + coords[:, 2]) * self.nx + coords[:, 3]
        canvas = features.new_zeros(batch_size * self.ny * self.nx, features.shape[1])
        canvas.index_copy_(0, flat, features)
        return canvas.view(batch_size, self.ny, self.nx, -1).permute(0, 3, 1, 2)


class BaseBEVBackbone(nn.Module):
    """2D backbone with upsampling and concatenation (OpenPCDet ``BaseBEVBackbone``)."""

    def __init__(self, cfg: ModelConfig, in_channels: int) -> None:
        super().__init__()
        self.blocks = nn.ModuleList()
        self.deblocks = nn.ModuleList()
        c_in = in_channels
        mom = cfg.bn_momentum
        for n_layers, stride, c, up, c_up in zip(
            cfg.layer_nums, cfg.layer_strides, cfg.num_filters, cfg.upsample_strides,
            cfg.num_upsample_filters, strict=True,
        ):
            # OpenPCDet pads with nn.ZeroPad2d(1) before an unpadded strided conv: the same
            # zeros, but a copy of the canvas (and its backward) per block. The conv pads
            # itself here; an Identity keeps the parameter names (blocks.i.1.weight...).
            layers: list[nn.Module] = [
                nn.Identity(), nn.Conv2d(c_in, c, 3, stride=stride, padding=1, bias=False),
                _bn2d(c, mom), nn.ReLU(),
            ]
            for _ in range(n_layers):
                layers += [nn.Conv2d(c, c, 3, padding=1, bias=False), _bn2d(c, mom), nn.ReLU()]
            self.blocks.append(nn.Sequential(*layers))
            if up >= 1:
                self.deblocks.append(nn.Sequential(
                    nn.ConvTranspose2d(c, c_up, up, stride=up, bias=False), _bn2d(c_up, mom), nn.ReLU()
                ))
            else:
                s = int(round(1 / up))
                self.deblocks.append(nn.Sequential(
                    nn.Conv2d(c, c_up, s, stride=s, bias=False), _bn2d(c_up, mom), nn.ReLU()
                ))
            c_in = c
        self.out_channels = sum(cfg.num_upsample_filters)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        ups = []
        for block, deblock in zip(self.blocks, self.deblocks, strict=True):
            x = block(x)
            ups.append(deblock(x))
        return torch.cat(ups, dim=1) if len(ups) > 1 else ups[0]


class AnchorHeadSingle(nn.Module):
    """1x1 convolutions for class, box residuals and direction (OpenPCDet ``AnchorHeadSingle``)."""

    def __init__(self, cfg: ModelConfig, in_channels: int) -> None:
        super().__init__()
        self.num_anchors_per_location = len(cfg.anchor.rotations_rad)
        a, c = self.num_anchors_per_location, cfg.num_classes
        self.num_classes = c
        self.num_dir_bins = cfg.num_dir_bins
        self.conv_cls = nn.Conv2d(in_channels, a * c, 1)
        self.conv_box = nn.Conv2d(in_channels, a * 7, 1)
        self.conv_dir_cls = (
            nn.Conv2d(in_channels, a * cfg.num_dir_bins, 1) if cfg.use_direction_classifier
            else None
        )
        self.init_weights()

    def init_weights(self) -> None:
        """OpenPCDet's init: class prior pi = 0.01 in the class bias, tiny box weights."""
        pi = 0.01
        nn.init.constant_(self.conv_cls.bias, -math.log((1 - pi) / pi))
        nn.init.normal_(self.conv_box.weight, mean=0.0, std=0.001)
        nn.init.zeros_(self.conv_box.bias)

    def forward(self, x: torch.Tensor) -> dict[str, torch.Tensor]:
        # The three 1x1 convolutions run as one over their stacked weights (the same sums;
        # one pass over the 384-channel map forward and backward instead of three).
        b = x.shape[0]
        convs = [self.conv_cls, self.conv_box]
        if self.conv_dir_cls is not None:
            convs.append(self.conv_dir_cls)
        y = F.conv2d(x, torch.cat([c.weight for c in convs]), torch.cat([c.bias for c in convs]))
        parts = y.split([c.out_channels for c in convs], dim=1)

        def flat(t: torch.Tensor, k: int) -> torch.Tensor:
            return t.permute(0, 2, 3, 1).reshape(b, -1, k)

        out = {"cls_preds": flat(parts[0], self.num_classes), "box_preds": flat(parts[1], 7)}
        if self.conv_dir_cls is not None:
            out["dir_preds"] = flat(parts[2], self.num_dir_bins)
        return out


@dataclass(frozen=True)
class Detections:
    """Detections of one frame.

    Attributes
    ----------
    boxes : (K, 7) float32 — ``x y z dx dy dz heading`` [m, rad].
    scores : (K,) float32 — confidence in [0, 1].
    labels : (K,) int64 — 1-based class index into ``ModelConfig.class_names``.
    """

    boxes: torch.Tensor
    scores: torch.Tensor
    labels: torch.Tensor


class PointPillars(nn.Module):
    """PointPillars detector; ``PointPillars()`` is the paper's model (§6.1).

    Parameters
    ----------
    cfg : ModelConfig, optional — architecture; defaults to the paper's door detector.

    Use::

        model = PointPillars()
        out = model(points, batch_size)           # points: (N, 1 + C) [batch, x, y, z, ...]
        loss, parts = model.loss(out, gt_boxes)   # gt_boxes: (B, M, 8) [box, class id]
        dets = model.predict(out)                 # list of Detections, one per frame
    """

    def __init__(self, cfg: ModelConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg = cfg if cfg is not None else ModelConfig()
        if cfg.num_classes != 1:
            raise ValueError(
                f"model.class_names={cfg.class_names}: only one class is supported "
                "(one anchor size per model); train one model per class"
            )
        self.vfe = PillarVFE(cfg)
        self.map_to_bev = PointPillarScatter(cfg, self.vfe.out_channels)
        self.backbone_2d = BaseBEVBackbone(cfg, self.vfe.out_channels)
        self.dense_head = AnchorHeadSingle(cfg, self.backbone_2d.out_channels)
        self.register_buffer("anchors", generate_anchors(cfg), persistent=False)
        self.register_buffer(
            "code_weights", torch.tensor(cfg.code_weights, dtype=torch.float32), persistent=False
        )
        self._dense_impl = self._dense

    # ------------------------------------------------------------------ forward
    def _dense(self, voxels, num_points, coords, batch_size: int) -> dict[str, torch.Tensor]:
        feats = self.vfe(voxels, num_points, coords)
        bev = self.map_to_bev(feats, coords, batch_size)
        return self.dense_head(self.backbone_2d(bev))

    def compile_dense(self, **kwargs) -> None:
        """Run VFE..head through ``torch.compile`` (voxelisation stays eager: dynamic sizes)."""
        kwargs.setdefault("dynamic", True)
        self._dense_impl = torch.compile(self._dense, **kwargs)

    def check_points(self, points: torch.Tensor) -> None:
        """Raise a clear error when the point columns do not match the config."""
        expected = 1 + self.cfg.num_point_features
        if points.ndim != 2 or points.shape[1] != expected:
            raise ValueError(
                f"points must be (N, 1 + num_point_features) = (N, {expected}) [batch index, x, "
                f"y, z, {self.cfg.num_point_features - 3} extra feature(s)], got "
                f"{tuple(points.shape)}; set model.num_point_features to match the data"
            )

    def forward(self, points: torch.Tensor, batch_size: int) -> dict[str, torch.Tensor]:
        """Voxelise and run the network.

        Parameters
        ----------
        points : (N, 1 + C) float — batch index, x, y, z [m], extra features.
        batch_size : frames in the batch.

        Returns
        -------
        dict with ``cls_preds`` (B, A, 1) logits, ``box_preds`` (B, A, 7) residuals and
        ``dir_preds`` (B, A, 2) logits, A = number of anchors.
        """
        self.check_points(points)
        pillars = voxelize(
            points, batch_size, self.cfg.point_cloud_range_m, self.cfg.voxel_size_m,
            self.cfg.max_points_per_voxel,
            self.cfg.max_voxels_train if self.training else self.cfg.max_voxels_test,
        )
        return self._dense_impl(pillars.voxels, pillars.num_points, pillars.coords, batch_size)

    # ------------------------------------------------------------------ training
    def loss(
        self, out: dict[str, torch.Tensor], gt_boxes: torch.Tensor
    ) -> tuple[torch.Tensor, dict[str, float]]:
        """OpenPCDet ``AnchorHeadTemplate.get_loss`` for one class.

        Parameters
        ----------
        out : forward() output.
        gt_boxes : (B, M, 8) — boxes [m, rad] + 1-based class id (0 = padding).

        Returns
        -------
        total loss (scalar tensor) and its parts as floats (``cls``, ``loc``, ``dir``).
        """
        cfg = self.cfg
        cls_preds = out["cls_preds"].float()
        box_preds = out["box_preds"].float()
        batch = cls_preds.shape[0]
        labels, box_targets, _ = assign_targets(
            self.anchors, gt_boxes.to(self.anchors.dtype), cfg.anchor.matched_threshold,
            cfg.anchor.unmatched_threshold,
        )
        positives = labels > 0
        negatives = labels == 0
        pos_norm = positives.sum(1, keepdim=True).float().clamp(min=1.0)
        cls_weights = (positives | negatives).float() / pos_norm
        reg_weights = positives.float() / pos_norm

        one_hot = F.one_hot(labels.clamp(min=0), cfg.num_classes + 1)[..., 1:].float()
        cls_loss = (sigmoid_focal_loss(cls_preds, one_hot, cfg.focal_alpha, cfg.focal_gamma)
                    * cls_weights[..., None]).sum() / batch * cfg.cls_weight

        p_sin, t_sin = add_sin_difference(box_preds, box_targets)
        loc = weighted_smooth_l1(p_sin, t_sin, cfg.smooth_l1_beta, self.code_weights)
        loc_loss = (loc.sum(-1) * reg_weights).sum() / batch * cfg.loc_weight
        total = cls_loss + loc_loss
        parts = {"cls": float(cls_loss.detach()), "loc": float(loc_loss.detach())}
        if "dir_preds" in out:
            dir_t = direction_targets(self.anchors[None], box_targets, cfg.dir_offset_rad,
                                      cfg.num_dir_bins)
            ce = F.cross_entropy(out["dir_preds"].float().reshape(-1, cfg.num_dir_bins),
                                 dir_t.reshape(-1), reduction="none").view(batch, -1)
            dir_loss = (ce * reg_weights).sum() / batch * cfg.dir_weight
            total = total + dir_loss
            parts["dir"] = float(dir_loss.detach())
        parts["total"] = float(total.detach())
        return total, parts

    # ------------------------------------------------------------------ inference
    def decode(self, out: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
        """Boxes (B, A, 7) [m, rad] and class scores (B, A, C) in [0, 1] for every anchor."""
        cfg = self.cfg
        boxes = decode_boxes(out["box_preds"].float(), self.anchors[None])
        if "dir_preds" in out:
            period = 2 * math.pi / cfg.num_dir_bins
            dir_labels = out["dir_preds"].argmax(dim=-1)
            rot = limit_period(boxes[..., 6] - cfg.dir_offset_rad, cfg.dir_limit_offset, period)
            heading = rot + cfg.dir_offset_rad + period * dir_labels.to(boxes.dtype)
            boxes = torch.cat([boxes[..., :6], heading[..., None]], dim=-1)
        return boxes, torch.sigmoid(out["cls_preds"].float())

    @torch.no_grad()
    def predict(self, out: dict[str, torch.Tensor]) -> list[Detections]:
        """Score threshold, top-k and rotated NMS per frame (OpenPCDet post-processing)."""
        cfg = self.cfg
        boxes, scores = self.decode(out)
        results = []
        for b in range(boxes.shape[0]):
            s, lab = scores[b].max(dim=-1)
            keep = s > cfg.score_threshold
            bx, s, lab = boxes[b][keep], s[keep], lab[keep]
            idx = rotated_nms(bx, s, cfg.nms_threshold, cfg.nms_pre_max, cfg.nms_post_max)
            results.append(Detections(boxes=bx[idx], scores=s[idx], labels=lab[idx] + 1))
        return results

    # ------------------------------------------------------------------ transfer
    def encoder_state_dict(self) -> dict[str, torch.Tensor]:
        """Parameters and buffers of VFE + scatter + backbone (the transferable encoder)."""
        return {k: v for k, v in self.state_dict().items()
                if k.split(".", 1)[0] in ENCODER_MODULES}

    def load_encoder(self, state_dict: dict[str, torch.Tensor]) -> list[str]:
        """Load only the encoder entries of ``state_dict`` (a full model or encoder state).

        Returns the loaded keys. Raises ``ValueError`` if an encoder key is missing or has a
        different shape (e.g. a checkpoint trained with another ``num_point_features``).
        """
        own = self.encoder_state_dict()
        missing = [k for k in own if k not in state_dict]
        if missing:
            raise ValueError(f"checkpoint lacks encoder weights {missing[:5]}... "
                             f"({len(missing)} of {len(own)} missing)")
        bad = [f"{k}: checkpoint {tuple(state_dict[k].shape)} vs model {tuple(v.shape)}"
               for k, v in own.items() if state_dict[k].shape != v.shape]
        if bad:
            raise ValueError("encoder shapes differ from the checkpoint (was it trained with "
                             "another model config?): " + "; ".join(bad[:5]))
        self.load_state_dict({k: state_dict[k] for k in own}, strict=False)
        return list(own)


#: One model is built at a time: :func:`seeded_model` points torch.nn.init at its own generator
#: for the duration of the build.
_BUILD_LOCK = threading.Lock()


@contextlib.contextmanager
def _initialisers_drawing_from(generator: torch.Generator) -> Iterator[None]:
    """torch.nn.init's random initialisers (which every module's ``reset_parameters`` and
    :meth:`AnchorHeadSingle.init_weights` call) draw from ``generator`` unless given one."""
    names = ("uniform_", "normal_", "trunc_normal_", "kaiming_uniform_", "kaiming_normal_",
             "xavier_uniform_", "xavier_normal_", "orthogonal_", "sparse_")
    saved = {name: getattr(nn.init, name) for name in names}

    def bound(init):
        def draw(*args, **kwargs):
            kwargs.setdefault("generator", generator)
            return init(*args, **kwargs)
        return draw

    try:
        for name, init in saved.items():
            setattr(nn.init, name, bound(init))
        yield
    finally:
        for name, init in saved.items():
            setattr(nn.init, name, init)


def seeded_model(cfg: ModelConfig | None, seed: int) -> PointPillars:
    """``PointPillars(cfg)`` with its initial weights drawn from a generator of its own seeded
    with ``seed``: the weights ``torch.manual_seed(seed)`` then ``PointPillars(cfg)`` gives, but
    untouched by anything else that uses torch's global generator meanwhile — another training
    run in a thread of this process saving and restoring that generator's state around its
    epoch hook, a DataLoader drawing its base seed, a hook of its own (those interleavings
    once gave a run other initial weights than its seed's; tests/detect/test_train.py). The
    global generator is neither read nor advanced. Build every model of a process through
    this function (:func:`~sim2radar.detect.train.load_checkpoint` does): a module built
    elsewhere during a build would draw its initial weights from this build's generator."""
    with _BUILD_LOCK, _initialisers_drawing_from(torch.Generator().manual_seed(int(seed))):
        return PointPillars(cfg)
