"""PointPillars door detector in pure PyTorch: model, training, encoder transfer, evaluation.

Entry points::

    from sim2radar.detect import PointPillars, load_config, train, evaluate_checkpoint

    model = PointPillars()                            # the paper's model (§6.1)
    cfg = load_config("configs/detect/pointpillars_door.yaml")
    result = train(cfg, out_dir="runs/baseline", seed=0)
    ap = evaluate_checkpoint(result.checkpoint, data_dir=cfg.data.root, split="test")
"""

from sim2radar.detect.config import (
    AnchorConfig,
    AugmentConfig,
    DataConfig,
    DetectConfig,
    ModelConfig,
    OptimConfig,
    RuntimeConfig,
    load_config,
)
from sim2radar.detect.model import ENCODER_MODULES, Detections, PointPillars
from sim2radar.detect.nms import rotated_nms
from sim2radar.detect.voxelize import Pillars, voxelize

__all__ = [
    "ENCODER_MODULES",
    "AnchorConfig",
    "AugmentConfig",
    "DataConfig",
    "DetectConfig",
    "Detections",
    "ModelConfig",
    "OptimConfig",
    "Pillars",
    "PointPillars",
    "RuntimeConfig",
    "load_config",
    "rotated_nms",
    "voxelize",
]
