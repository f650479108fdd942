"""Stage 3 ``oracle`` backend: the ground-truth material under each segment."""

from __future__ import annotations

from sim2radar.reconstruct._gt import gt_array, majority
from sim2radar.reconstruct.types import (
    MATERIAL_BACKENDS,
    DepthResult,
    FrameInput,
    MaterialLabel,
    Segments,
)
from sim2radar.vocab import MATERIAL_CLASSES

__all__ = ["OracleMaterials"]


@MATERIAL_BACKENDS.register("oracle")
class OracleMaterials:
    """Majority ground-truth material per segment; confidence = its pixel fraction.

    Parameters
    ----------
    ground_truth : ``WorldFrame``-like or dict with ``material_id`` (H, W) into
        ``vocab.MATERIAL_CLASSES``.
    """

    def __init__(self, ground_truth=None) -> None:
        self.ground_truth = ground_truth

    def label(self, frame: FrameInput, depth: DepthResult, segments: Segments) -> list[MaterialLabel]:
        mat = gt_array(self.ground_truth, "material_id", frame, "material")
        winner, frac = majority(mat, segments.segment_id, segments.n_segments)
        return [
            MaterialLabel(MATERIAL_CLASSES[int(w)], float(f), "ground truth (majority of pixels)")
            for w, f in zip(winner, frac, strict=True)
        ]
