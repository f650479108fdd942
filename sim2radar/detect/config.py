"""Typed configuration of the PointPillars detector, its training and its data.

Every default is the paper's setting (§6.1) or, where the paper is silent, OpenPCDet's
``tools/cfgs/kitti_models/pointpillar.yaml``. A YAML file mirrors :class:`DetectConfig`::

    data:
      root: ../../data/ifr          # OpenPCDet custom layout; relative to this YAML file
    model:
      anchor: {size_m: [0.95, 0.20, 2.05]}
    optimization: {epochs: 200, batch_size: 8, lr: 0.003}
    pretrained_encoder: null        # or a checkpoint path: VFE + scatter + backbone are loaded

Door statistics behind the anchor defaults (``AnchorConfig``): single interior doors are
0.8-1.0 m wide (DIN 18101 / ADA 32" clear = 0.81 m), door leaves 0.04 m thick in frames on walls
of 0.10-0.25 m, so box depth across the wall is ~0.1-0.3 m; door height 2.0-2.1 m
(DIN 18101: 2.01 m / 2.135 m); the radar is mounted 1.05 m above the floor (IFR rig,
``sim2radar.worlds.config.RigConfig.radar_position_m``), so a door's bottom is at z = -1.05 m.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from sim2radar.configio import config_path, read_yaml_mapping

__all__ = [
    "AnchorConfig",
    "AugmentConfig",
    "DataConfig",
    "DetectConfig",
    "ModelConfig",
    "OptimConfig",
    "RuntimeConfig",
    "load_config",
]


class _Frozen(BaseModel):
    model_config = ConfigDict(frozen=True, extra="forbid")


class AnchorConfig(_Frozen):
    """One anchor class (OpenPCDet ``ANCHOR_GENERATOR_CONFIG`` entry + target assigner)."""

    #: anchor box size dx (along heading, door width), dy (across the wall), dz (height) [m]
    size_m: tuple[float, float, float] = (0.95, 0.20, 2.05)
    #: anchor headings [rad]; two rotations as in OpenPCDet
    rotations_rad: tuple[float, ...] = (0.0, math.pi / 2)
    #: anchor bottom height (z of the floor in the radar frame) [m]
    bottom_height_m: float = -1.05
    #: BEV IoU (axis-aligned nearest-box) at or above which an anchor is positive
    matched_threshold: float = 0.5
    #: BEV IoU below which an anchor is negative (between the two: ignored). Doors are thin like
    #: OpenPCDet's pedestrians, so their 0.5 / 0.35 pair is used (cars use 0.6 / 0.45).
    unmatched_threshold: float = 0.35
    #: place anchors at cell centres (True) or spread them edge to edge (OpenPCDet: False)
    align_center: bool = False

    @model_validator(mode="after")
    def _check(self) -> AnchorConfig:
        if any(s <= 0 for s in self.size_m):
            raise ValueError(f"anchor.size_m must be positive, got {self.size_m}")
        if not self.rotations_rad:
            raise ValueError("anchor.rotations_rad needs at least one rotation")
        if not 0 <= self.unmatched_threshold <= self.matched_threshold <= 1:
            raise ValueError(
                "need 0 <= anchor.unmatched_threshold <= anchor.matched_threshold <= 1, got "
                f"{self.unmatched_threshold}, {self.matched_threshold}"
            )
        return self


class ModelConfig(_Frozen):
    """PointPillars architecture, anchors, losses and post-processing."""

    class_names: tuple[str, ...] = ("door",)
    #: x_min, y_min, z_min, x_max, y_max, z_max [m] in the radar frame
    point_cloud_range_m: tuple[float, float, float, float, float, float] = (
        -1.0, -5.2, -1.5, 5.4, 5.2, 2.5,
    )
    #: pillar size x, y, z [m]; z spans the whole range (pillars)
    voxel_size_m: tuple[float, float, float] = (0.05, 0.05, 4.0)
    #: points per pillar kept (the rest dropped), OpenPCDet MAX_POINTS_PER_VOXEL
    max_points_per_voxel: int = 32
    max_voxels_train: int = 16000
    max_voxels_test: int = 40000
    #: point columns: x, y, z [m] + extra features (e.g. intensity); checked against the data
    num_point_features: int = 4
    vfe_filters: tuple[int, ...] = (64,)
    #: BatchNorm momentum (OpenPCDet 0.01: running statistics settle over ~500 steps; short
    #: runs of a few dozen steps need ~0.1 for eval-mode outputs to match training)
    bn_momentum: float = 0.01
    layer_nums: tuple[int, ...] = (3, 5, 5)
    layer_strides: tuple[int, ...] = (2, 2, 2)
    num_filters: tuple[int, ...] = (64, 128, 256)
    upsample_strides: tuple[int, ...] = (1, 2, 4)
    num_upsample_filters: tuple[int, ...] = (128, 128, 128)
    anchor: AnchorConfig = AnchorConfig()
    use_direction_classifier: bool = True
    dir_offset_rad: float = 0.78539
    dir_limit_offset: float = 0.0
    num_dir_bins: int = 2
    #: loss weights: classification, localisation, direction (OpenPCDet 1.0 / 2.0 / 0.2)
    cls_weight: float = 1.0
    loc_weight: float = 2.0
    dir_weight: float = 0.2
    code_weights: tuple[float, ...] = (1.0,) * 7
    focal_alpha: float = 0.25
    focal_gamma: float = 2.0
    smooth_l1_beta: float = 1.0 / 9.0
    #: post-processing (OpenPCDet POST_PROCESSING)
    score_threshold: float = 0.1
    nms_threshold: float = 0.01
    nms_pre_max: int = 4096
    nms_post_max: int = 500

    @field_validator("num_point_features")
    @classmethod
    def _min_features(cls, v: int) -> int:
        if v < 3:
            raise ValueError(f"num_point_features must be >= 3 (x, y, z), got {v}")
        return v

    @model_validator(mode="after")
    def _check_grid(self) -> ModelConfig:
        r, v = self.point_cloud_range_m, self.voxel_size_m
        for axis in range(3):
            n = (r[axis + 3] - r[axis]) / v[axis]
            if r[axis + 3] <= r[axis] or abs(n - round(n)) > 1e-4:
                raise ValueError(
                    f"point_cloud_range_m {r} must be a whole number of voxel_size_m {v} "
                    f"along axis {'xyz'[axis]} (got {n:.4f} voxels)"
                )
        if round((r[5] - r[2]) / v[2]) != 1:
            raise ValueError("PointPillars needs one voxel along z: voxel_size_m[2] = z range")
        n = len(self.layer_nums)
        if not (len(self.layer_strides) == len(self.num_filters) == len(self.upsample_strides)
                == len(self.num_upsample_filters) == n):
            raise ValueError("layer_nums, layer_strides, num_filters, upsample_strides and "
                             "num_upsample_filters must have the same length")
        nx, ny = self.grid_size[:2]
        total = math.prod(self.layer_strides)
        if nx % total or ny % total:
            raise ValueError(
                f"BEV grid {nx}x{ny} must be divisible by the backbone's total stride {total}"
            )
        if len(self.code_weights) != 7:
            raise ValueError("code_weights needs 7 entries (x y z dx dy dz heading)")
        return self

    @property
    def grid_size(self) -> tuple[int, int, int]:
        """Voxel grid (nx, ny, nz)."""
        r, v = self.point_cloud_range_m, self.voxel_size_m
        return tuple(int(round((r[i + 3] - r[i]) / v[i])) for i in range(3))  # type: ignore[return-value]

    @property
    def feature_map_stride(self) -> int:
        """Stride of the head's feature map w.r.t. the BEV grid (2 for the default)."""
        return int(round(self.layer_strides[0] / self.upsample_strides[0]))

    @property
    def num_classes(self) -> int:
        return len(self.class_names)


class DataConfig(_Frozen):
    """Where the dataset lives (OpenPCDet custom layout) and which split is which."""

    #: dataset folder with points/, labels/, ImageSets/; relative to the YAML file
    root: Path | None = None
    #: point files with more columns than ``model.num_point_features`` keep the first ones
    #: (OpenPCDet's ``used_feature_list``), e.g. x y z intensity of the reference radar's
    #: x y z intensity doppler; False refuses them
    drop_extra_point_columns: bool = True
    train_split: str = "train"
    val_split: str = "val"
    test_split: str = "test"


class AugmentConfig(_Frozen):
    """Training-only augmentation (OpenPCDet DATA_AUGMENTOR for KITTI PointPillars)."""

    gt_sampling: bool = True
    #: target number of boxes per class after GT sampling (OpenPCDet SAMPLE_GROUPS "door:6")
    sample_groups: dict[str, int] = Field(default_factory=lambda: {"door": 6})
    #: database entries need at least this many points (OpenPCDet filter_by_min_points)
    min_points_in_gt: int = 5
    random_flip_x: bool = True
    #: global rotation about z [rad] (OpenPCDet WORLD_ROT_ANGLE)
    rotation_range_rad: tuple[float, float] = (-0.78539816, 0.78539816)
    #: global scaling factor (OpenPCDet WORLD_SCALE_RANGE)
    scale_range: tuple[float, float] = (0.95, 1.05)
    shuffle_points: bool = True
    #: the order of random draws behind the augmentation (sim2radar.detect.batches): batch k of
    #: epoch e draws from child k of SeedSequence([seed, e]), so a batch does not depend on
    #: the DataLoader worker that made it. The only order this code makes; a config field so
    #: that it is part of a run's identity (runs before issue #31 drew every batch of an epoch
    #: from one stream and have no such field)
    random_draws: Literal["per_batch"] = "per_batch"


class OptimConfig(_Frozen):
    """AdamW + OpenPCDet's one-cycle schedule (``adam_onecycle``)."""

    batch_size: int = 8
    epochs: int = 200
    lr: float = 0.003
    weight_decay: float = 0.01
    betas: tuple[float, float] = (0.9, 0.99)
    moms: tuple[float, float] = (0.95, 0.85)
    pct_start: float = 0.4
    div_factor: float = 10.0
    final_div_factor: float = 1e4
    grad_norm_clip: float = 10.0
    #: the encoder's (VFE + scatter + backbone) learning rate as a share of ``lr``, the head
    #: keeping ``lr``: discriminative fine-tuning of a transferred encoder (Howard & Ruder,
    #: "Universal Language Model Fine-tuning", ACL 2018, §3.2); 1.0 (every parameter at
    #: ``lr``) is the paper's protocol
    encoder_lr_scale: float = 1.0

    @field_validator("batch_size", "epochs")
    @classmethod
    def _positive(cls, v: int) -> int:
        if v < 1:
            raise ValueError(f"must be >= 1, got {v}")
        return v

    @field_validator("encoder_lr_scale")
    @classmethod
    def _scale(cls, v: float) -> float:
        if not 0.0 < v <= 1.0:
            raise ValueError(f"must lie in (0, 1] (a share of lr), got {v}")
        return v


class RuntimeConfig(_Frozen):
    """Hardware and bookkeeping; none of it changes the maths."""

    #: "cpu", "cuda", "cuda:1"...; None picks via sim2radar.hardware.torch_device()
    device: str | None = None
    #: mixed precision: true (bfloat16 autocast on a CPU, bfloat16 or float16 on CUDA), false
    #: (float32), or "auto": true on CUDA and on CPUs with native bfloat16 (AVX-512 BF16 / AMX),
    #: false elsewhere (sim2radar.hardware.autocast_dtype). The A/B that made "auto" the
    #: default (baseline AP unchanged within noise, 1.9x faster steps) is in BENCHMARKS.md
    amp: bool | Literal["auto"] = "auto"
    #: wrap the dense network (VFE..head) in torch.compile
    compile: bool = False
    #: torch intra-op threads on CPU (None: torch's default)
    num_threads: int | None = None
    #: save a checkpoint every this many epochs (the last epoch always saves)
    checkpoint_every: int = 10
    #: keep this many epoch checkpoints besides ``last.pt``
    keep_checkpoints: int = 2
    #: write ``last.pt`` at most every this many seconds of training (0: after every epoch).
    #: An epoch checkpoint (``checkpoint_every``) and the final epoch always write it too, so a
    #: killed run resumes losing at most this long (plus the epoch under way). Short epochs
    #: (a CPU demo: ~60 ms) made the per-epoch write a sixth of a run's time (issue #31)
    last_every_s: float = Field(30.0, ge=0.0)
    #: torch DataLoader worker processes that augment and collate the training batches ahead
    #: of the model's step (0: in this process, each just before its step); the same batches
    #: bit for bit for any count (sim2radar.detect.batches). "auto": 0 on a CPU, where workers
    #: only compete with the model's threads for the cores (measured on 2 cores, BENCHMARKS.md,
    #: issue #31), 2 on CUDA (sim2radar.detect.batches.resolve_loader_workers)
    loader_workers: int | Literal["auto"] = "auto"
    #: batches each DataLoader worker prepares ahead (loader_workers > 0)
    loader_prefetch: int = Field(2, ge=1, le=16)
    #: deprecated, ignored: the background thread it sized is gone (issue #31); configs and
    #: checkpoints that carry it still load (a warning when it is set); not written any more
    prefetch_batches: int | None = Field(None, ge=0, le=8, exclude=True)
    progress: bool = True

    @field_validator("loader_workers", mode="before")
    @classmethod
    def _workers(cls, v: Any) -> Any:
        if isinstance(v, bool) or (isinstance(v, int) and not 0 <= v <= 64):
            raise ValueError(f"must be 'auto' or an int in [0, 64], got {v}")
        return v

    @field_validator("prefetch_batches")
    @classmethod
    def _deprecated_prefetch(cls, v: int | None) -> int | None:
        if v is not None:
            warnings.warn("runtime.prefetch_batches is deprecated and ignored: training batches "
                          "are made by runtime.loader_workers DataLoader workers (issue #31)",
                          FutureWarning, stacklevel=2)
        return v


class DetectConfig(_Frozen):
    """Everything one training run needs."""

    name: str = "pointpillars_door"
    seed: int = 0
    data: DataConfig = DataConfig()
    model: ModelConfig = ModelConfig()
    augmentation: AugmentConfig = AugmentConfig()
    optimization: OptimConfig = OptimConfig()
    runtime: RuntimeConfig = RuntimeConfig()
    #: checkpoint whose encoder (VFE + scatter + backbone) initialises the model; head is fresh
    pretrained_encoder: Path | None = None

    def with_updates(self, **sections: dict[str, Any] | Any) -> DetectConfig:
        """A copy with some fields replaced; dict values update a section field by field."""
        data = self.model_dump()
        for key, value in sections.items():
            if isinstance(value, dict) and isinstance(data.get(key), dict):
                data[key] = {**data[key], **value}
            else:
                data[key] = value
        return DetectConfig.model_validate(data)


def _resolve(path: Path | None, base: Path) -> Path | None:
    if path is None:
        return None
    path = Path(path).expanduser()
    return path if path.is_absolute() else (base / path).resolve()


def load_config(path: str | Path, **overrides: Any) -> DetectConfig:
    """Load a :class:`DetectConfig` from YAML; relative paths resolve against the YAML's folder.

    Parameters
    ----------
    path : YAML file.
    **overrides : top-level sections or fields to replace (see :meth:`DetectConfig.with_updates`).

    Raises
    ------
    FileNotFoundError, ValueError — naming the file and the offending field.
    """
    path = config_path(path, "detect", what="detector config")
    raw = read_yaml_mapping(path, what="detector config", missing_error=FileNotFoundError,
                            expect="a mapping of sections")
    try:
        cfg = DetectConfig.model_validate(raw)
    except ValidationError as exc:
        raise ValueError(f"{path}: invalid detector config:\n{exc}") from exc
    base = path.resolve().parent
    data = cfg.data.model_copy(update={"root": _resolve(cfg.data.root, base)})
    cfg = cfg.model_copy(
        update={"data": data, "pretrained_encoder": _resolve(cfg.pretrained_encoder, base)}
    )
    if overrides:
        cfg = cfg.with_updates(**overrides)
    return cfg
