"""Stage 1 ``oracle`` backend: the ground-truth depth of a procedural world."""

from __future__ import annotations

import numpy as np

from sim2radar.reconstruct._gt import gt_array
from sim2radar.reconstruct.types import DEPTH_BACKENDS, DepthResult, FrameInput

__all__ = ["OracleDepth"]


@DEPTH_BACKENDS.register("oracle")
class OracleDepth:
    """Ground-truth z-depth, optionally with multiplicative noise (to study error propagation).

    Parameters
    ----------
    ground_truth : ``WorldFrame``-like (``.depth_m``), a dict with ``depth_m``, or an (H, W) array.
    noise_rel : float — standard deviation of the relative Gaussian depth noise (0 = exact).
    seed : int — noise seed.
    """

    def __init__(self, ground_truth=None, *, noise_rel: float = 0.0, seed: int = 0) -> None:
        if noise_rel < 0:
            raise ValueError(f"oracle depth noise_rel must be >= 0, got {noise_rel}")
        self.ground_truth = ground_truth
        self.noise_rel = float(noise_rel)
        self.seed = int(seed)

    def estimate(self, frame: FrameInput) -> DepthResult:
        depth = gt_array(self.ground_truth, "depth_m", frame, "depth").astype(np.float32)
        depth = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
        if self.noise_rel > 0:
            rng = np.random.default_rng(self.seed)
            depth = depth * (1 + self.noise_rel * rng.standard_normal(depth.shape)).astype(np.float32)
            depth = np.clip(depth, 0, None)
        return DepthResult(depth, {"backend": "oracle", "noise_rel": self.noise_rel})
