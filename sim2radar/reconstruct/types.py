"""Stage interfaces of the reconstruction pipeline (paper §3) and their backend registries.

Data flows through four stages; each stage has a registry of named backends (DESIGN.md table):

    Stage 1 depth      DEPTH_BACKENDS     "moge" | "lidar" | "oracle"
    Stage 2 segments   SEGMENT_BACKENDS   "sam2-gdino" | "builtin" | "oracle"
    Stage 3 materials  MATERIAL_BACKENDS  "vlm" | "prior" | "oracle"
    Stage 4 3D         (back-projection, meshing, door boxes; no backends)

A backend is a class registered under its name, constructed with its own keyword options (paths to
user-supplied model files, server URL, ...) and, for ``oracle`` backends, the ground truth.
Every backend receives a :class:`FrameInput` and returns the stage's result dataclass.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np

from sim2radar.camera import CameraIntrinsics
from sim2radar.registry import Registry

__all__ = [
    "FrameInput",
    "DepthResult",
    "Segments",
    "MaterialLabel",
    "DepthBackend",
    "SegmentBackend",
    "MaterialBackend",
    "DEPTH_BACKENDS",
    "SEGMENT_BACKENDS",
    "MATERIAL_BACKENDS",
    "ReconstructionInputError",
]


class ReconstructionInputError(ValueError):
    """Bad input to reconstruction (image, intrinsics, LiDAR); the message says what and how to fix."""


@dataclasses.dataclass(frozen=True, eq=False)
class FrameInput:
    """One RGB frame to reconstruct.

    Attributes
    ----------
    rgb : (H, W, 3) uint8
    intrinsics : CameraIntrinsics — must match the image size.
    lidar_points : (N, 3) float32 or None — sparse LiDAR in the *camera* frame (OpenCV: x right,
        y down, z forward) [m]; gives metric scale when present.
    name : str — identifier used in logs, errors and artifact keys.
    """

    rgb: np.ndarray
    intrinsics: CameraIntrinsics
    lidar_points: np.ndarray | None = None
    name: str = "frame"

    def __post_init__(self) -> None:
        rgb = np.asarray(self.rgb)
        k = self.intrinsics
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ReconstructionInputError(
                f"{self.name}: rgb must be (H, W, 3), got shape {rgb.shape}"
            )
        if rgb.dtype != np.uint8:
            raise ReconstructionInputError(
                f"{self.name}: rgb must be uint8 (0..255), got {rgb.dtype}; convert with "
                "(img * 255).clip(0, 255).astype(np.uint8) if it is float in [0, 1]"
            )
        if not isinstance(k, CameraIntrinsics):
            raise ReconstructionInputError(f"{self.name}: intrinsics must be a CameraIntrinsics")
        if (rgb.shape[1], rgb.shape[0]) != (k.width, k.height):
            raise ReconstructionInputError(
                f"{self.name}: image is {rgb.shape[1]}x{rgb.shape[0]} but intrinsics say "
                f"{k.width}x{k.height}; pass the intrinsics of this image (or .scaled())"
            )
        if self.lidar_points is not None:
            pts = np.asarray(self.lidar_points, dtype=np.float32)
            if pts.ndim != 2 or pts.shape[1] != 3:
                raise ReconstructionInputError(
                    f"{self.name}: lidar_points must be (N, 3), got {pts.shape}"
                )
            if not np.isfinite(pts).all():
                raise ReconstructionInputError(
                    f"{self.name}: lidar_points contain NaN/inf "
                    f"({int((~np.isfinite(pts)).any(axis=1).sum())} rows); drop them first"
                )
            object.__setattr__(self, "lidar_points", pts)

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.rgb.shape[0]), int(self.rgb.shape[1])


@dataclasses.dataclass(frozen=True, eq=False)
class DepthResult:
    """Stage 1 output. ``depth_m`` (H, W) float32 z-depth [m], 0 where invalid; ``info`` holds
    diagnostics (e.g. alignment scale/shift, number of LiDAR points used)."""

    depth_m: np.ndarray
    info: dict = dataclasses.field(default_factory=dict)


@dataclasses.dataclass(frozen=True, eq=False)
class Segments:
    """Stage 2 output.

    Attributes
    ----------
    segment_id : (H, W) int32 — segment index per pixel, -1 for unassigned pixels.
    labels : tuple[str, ...] — semantic class per segment (names from ``vocab.SEMANTIC_CLASSES``).
    scores : (S,) float32 — label confidence per segment in [0, 1].
    """

    segment_id: np.ndarray
    labels: tuple[str, ...]
    scores: np.ndarray

    @property
    def n_segments(self) -> int:
        return len(self.labels)


@dataclasses.dataclass(frozen=True)
class MaterialLabel:
    """Stage 3 output for one segment: a material from ``vocab.MATERIAL_CLASSES``, a confidence
    in [0, 1], and the reason (the VLM's reasoning, the rule that fired, or why it fell back)."""

    material: str
    confidence: float
    reason: str = ""


class DepthBackend(Protocol):
    def estimate(self, frame: FrameInput) -> DepthResult: ...


class SegmentBackend(Protocol):
    def segment(self, frame: FrameInput, depth: DepthResult) -> Segments: ...


class MaterialBackend(Protocol):
    def label(
        self, frame: FrameInput, depth: DepthResult, segments: Segments
    ) -> list[MaterialLabel]: ...


DEPTH_BACKENDS: Registry[type] = Registry("depth")
SEGMENT_BACKENDS: Registry[type] = Registry("segmentation")
MATERIAL_BACKENDS: Registry[type] = Registry("material")
