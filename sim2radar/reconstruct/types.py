"""Stage interfaces of the reconstruction pipeline (paper §3) and their backend registries.

Data flows through four stages; each stage has a registry of named backends (docs/design.md, "Model backends"):

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
from typing import Any, Protocol

import numpy as np

from sim2radar.camera import CameraIntrinsics
from sim2radar.registry import Registry

__all__ = [
    "FrameInput",
    "up_from_pitch_roll",
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


def up_from_pitch_roll(pitch_deg: float, roll_deg: float = 0.0) -> np.ndarray:
    """Gravity up in the camera frame (OpenCV: x right, y down, z forward) of a camera pitched
    down by ``pitch_deg`` and rolled clockwise (as seen from behind) by ``roll_deg`` on a level
    rig [deg]. A level camera has up (0, −1, 0); pitched down, up tilts towards −z.
    """
    p, r = np.radians(float(pitch_deg)), np.radians(float(roll_deg))
    if not (np.isfinite(p) and np.isfinite(r) and abs(p) < np.pi / 2 and abs(r) < np.pi / 2):
        raise ValueError(f"pitch_deg and roll_deg must be finite and within ±90°, got "
                         f"{pitch_deg}, {roll_deg}")
    # pitched down, the optical axis z points partly down (up·z = −sin p); rolled, the x axis
    # turns towards y (down on the right), so up·x = −sin r cos p
    return np.array([-np.sin(r) * np.cos(p), -np.cos(r) * np.cos(p), -np.sin(p)])


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
    up_cam : (3,) float64 or None — gravity up (against gravity) in the camera frame, from the
        rig's calibration (a camera mounted at a known pitch and roll on a level cart: see
        :func:`up_from_pitch_roll`) or an IMU; stored unit length. None: estimated from the
        image and depth.
    camera_height_m : float or None [m] — the camera's height above the floor (rig
        calibration); gives the floor where the LiDAR has no return on it (e.g. facing a near
        wall, where its lowest beam hits the wall first).

    ``up_cam`` and ``camera_height_m`` are the rig calibration; the reconstruction uses them
    unless its config says ``rig_calibration: false``.
    """

    rgb: np.ndarray
    intrinsics: CameraIntrinsics
    lidar_points: np.ndarray | None = None
    name: str = "frame"
    up_cam: np.ndarray | None = None
    camera_height_m: float | None = None

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
        if self.up_cam is not None:
            up = np.asarray(self.up_cam, dtype=np.float64)
            norm = float(np.linalg.norm(up)) if up.shape == (3,) else 0.0
            if not (np.isfinite(up).all() and norm > 1e-6):
                raise ReconstructionInputError(
                    f"{self.name}: up_cam must be a finite non-zero 3-vector (gravity up in the "
                    f"camera frame: x right, y down, z forward), got {self.up_cam!r}"
                )
            object.__setattr__(self, "up_cam", up / norm)
        if self.camera_height_m is not None:
            height = float(self.camera_height_m)
            if not (np.isfinite(height) and 0 < height < 10):
                raise ReconstructionInputError(
                    f"{self.name}: camera_height_m must be the camera's height above the floor "
                    f"in metres, in (0, 10), got {self.camera_height_m!r}"
                )
            object.__setattr__(self, "camera_height_m", height)

    @property
    def rig_calibration(self) -> dict:
        """The rig calibration this frame carries, JSON-able (empty without one)."""
        out: dict = {}
        if self.up_cam is not None:
            out["up_cam"] = [round(float(x), 9) for x in self.up_cam]
        if self.camera_height_m is not None:
            out["camera_height_m"] = round(self.camera_height_m, 9)
        return out

    def without_rig_calibration(self) -> FrameInput:
        """This frame without ``up_cam`` and ``camera_height_m``."""
        return dataclasses.replace(self, up_cam=None, camera_height_m=None)

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.rgb.shape[0]), int(self.rgb.shape[1])


@dataclasses.dataclass(frozen=True, eq=False)
class DepthResult:
    """Stage 1 output. ``depth_m`` (H, W) float32 z-depth [m], 0 where invalid; ``info`` holds
    diagnostics (e.g. alignment scale/shift, number of LiDAR points used); ``confidence``
    (H, W) float32 in [0, 1] per pixel where the backend measures one (``lidar``), else None.
    Not stored: the depth artifact holds ``depth_m`` and ``info``."""

    depth_m: np.ndarray
    info: dict = dataclasses.field(default_factory=dict)
    confidence: np.ndarray | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class Segments:
    """Stage 2 output.

    Attributes
    ----------
    segment_id : (H, W) int32 — segment index per pixel, -1 for unassigned pixels.
    labels : tuple[str, ...] — semantic class per segment (names from ``vocab.SEMANTIC_CLASSES``).
    scores : (S,) float32 — label confidence per segment in [0, 1].
    up_cam : (3,) float64 or None — gravity up in the camera frame the segmentation worked in
        (its door boxes and labels assume it); None: the pipeline estimates gravity itself.
    door_boxes_level : (M, 7) float32 — doorways the segmentation measured (e.g. on rectified
        wall planes), ``x y z dx dy dz heading`` in the level frame of ``up_cam`` [m, rad];
        they take precedence over boxes fitted to door pixels. Empty when none.
    info : dict — JSON-able diagnostics (floor / ceiling level, detection counts, ...).
    detections : the open-vocabulary detector's raw detections where a backend ran one
        (``sam2-gdino``: its :class:`Detections`), else None. Not stored.
    """

    segment_id: np.ndarray
    labels: tuple[str, ...]
    scores: np.ndarray
    up_cam: np.ndarray | None = None
    door_boxes_level: np.ndarray = dataclasses.field(
        default_factory=lambda: np.zeros((0, 7), np.float32))
    info: dict = dataclasses.field(default_factory=dict)
    detections: Any = None

    def __post_init__(self) -> None:
        if self.up_cam is not None:
            object.__setattr__(self, "up_cam", np.asarray(self.up_cam, np.float64).reshape(3))
        object.__setattr__(self, "door_boxes_level",
                           np.asarray(self.door_boxes_level, np.float32).reshape(-1, 7))

    @property
    def n_segments(self) -> int:
        return len(self.labels)


@dataclasses.dataclass(frozen=True)
class MaterialLabel:
    """Stage 3 output for one segment: a material from ``vocab.MATERIAL_CLASSES``, a confidence
    in [0, 1], and the reason (the VLM's reasoning, the rule that fired, or why it fell back).

    ``fallback`` marks a label that stands in for an answer the backend could not get (a VLM
    request that failed, an unusable or out-of-vocabulary answer): the run goes on with it, but
    its artifacts are stored as provisional and the next run asks again
    (:meth:`sim2radar.storage.ArtifactStore.cached`).
    """

    material: str
    confidence: float
    reason: str = ""
    fallback: bool = False


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
