"""Pinhole camera model shared by worlds (rendering) and reconstruction (back-projection).

Convention: OpenCV. Camera frame x right, y down, z forward (optical axis); pixel (u, v) with u
along image columns, v along rows, origin at the top-left corner of the top-left pixel, so the
centre of pixel (row i, column j) is (u, v) = (j + 0.5, i + 0.5).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

__all__ = ["CameraIntrinsics", "back_project", "project"]


@dataclasses.dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics.

    Attributes
    ----------
    fx, fy : float [px] — focal lengths.
    cx, cy : float [px] — principal point.
    width, height : int [px] — image size.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy", "cx", "cy"):
            value = getattr(self, name)
            if not isinstance(value, int | float) or not math.isfinite(value):
                raise ValueError(f"intrinsics.{name} must be a finite number, got {value!r}")
        if self.fx <= 0 or self.fy <= 0:
            raise ValueError(f"intrinsics.fx/fy must be > 0, got fx={self.fx}, fy={self.fy}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(
                f"intrinsics.width/height must be positive, got {self.width}x{self.height}"
            )

    @classmethod
    def from_fov(cls, width: int, height: int, hfov_deg: float) -> CameraIntrinsics:
        """Square-pixel intrinsics with the principal point at the image centre."""
        if not 0 < hfov_deg < 180:
            raise ValueError(f"hfov_deg must lie in (0, 180), got {hfov_deg}")
        f = 0.5 * width / math.tan(math.radians(hfov_deg) / 2)
        return cls(f, f, width / 2, height / 2, int(width), int(height))

    @classmethod
    def from_matrix(cls, k: np.ndarray, width: int, height: int) -> CameraIntrinsics:
        k = np.asarray(k, dtype=np.float64)
        if k.shape != (3, 3):
            raise ValueError(f"intrinsics matrix must be (3, 3), got {k.shape}")
        return cls(float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), width, height)

    @classmethod
    def from_yaml(cls, path: str | Path) -> CameraIntrinsics:
        """Read ``fx, fy, cx, cy, width, height`` (or ``K: 3x3`` + ``width, height``) from YAML.

        Raises
        ------
        FileNotFoundError if the file is missing; ValueError naming the file, the field and the
        fix for a missing field, a non-number (``cx: [120.0]``) or a fractional image size
        (``width: 240.7``).
        """
        from sim2radar.configio import read_yaml_mapping, real_number, whole_number

        path = Path(path)
        doc = read_yaml_mapping(path, what="intrinsics file", missing_error=FileNotFoundError,
                                expect="a mapping with fx, fy, cx, cy, width, height")
        try:
            size = [whole_number(doc[k], path, k, minimum=1, example=e)
                    for k, e in (("width", 640), ("height", 480))]
            if "K" in doc:
                try:
                    kmat = np.asarray(doc["K"], dtype=np.float64)
                except (TypeError, ValueError):
                    kmat = None
                if kmat is None or kmat.shape != (3, 3) or not np.isfinite(kmat).all():
                    raise ValueError(f"{path}: K: must be a 3x3 matrix of numbers [px], got "
                                     f"{doc['K']!r}; write e.g. 'K: [[fx, 0, cx], [0, fy, cy], "
                                     "[0, 0, 1]]'")
                return cls.from_matrix(kmat, *size)
            return cls(*(real_number(doc[k], path, k, unit="px", example=e)
                         for k, e in (("fx", 500.0), ("fy", 500.0), ("cx", 320.0),
                                      ("cy", 240.0))), *size)
        except KeyError as exc:
            raise ValueError(
                f"{path}: missing field {exc.args[0]!r}; need fx, fy, cx, cy, width, height "
                "(or K and width, height)"
            ) from None
        except ValueError as exc:  # __post_init__'s checks (fx <= 0, ...) name no file
            msg = str(exc)
            raise ValueError(msg if msg.startswith(f"{path}: ") else f"{path}: {msg}") from None

    @property
    def matrix(self) -> np.ndarray:
        """(3, 3) float64 — the K matrix."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], dtype=np.float64)

    @property
    def hfov_rad(self) -> float:
        """Horizontal field of view [rad]."""
        return 2 * math.atan(self.width / (2 * self.fx))

    def scaled(self, factor: float) -> CameraIntrinsics:
        """Intrinsics for the image resized by ``factor``."""
        return CameraIntrinsics(self.fx * factor, self.fy * factor, self.cx * factor,
                                self.cy * factor, round(self.width * factor),
                                round(self.height * factor))

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def back_project(depth_m: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Back-project a z-depth image to camera-frame points.

    Parameters
    ----------
    depth_m : (H, W) float — z-depth along the optical axis [m]; 0 or NaN where invalid.

    Returns
    -------
    (H, W, 3) float32 — x, y, z [m] per pixel centre (camera frame); NaN where invalid.
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    h, w = depth.shape
    if (w, h) != (intrinsics.width, intrinsics.height):
        raise ValueError(f"depth is {w}x{h} but intrinsics are {intrinsics.width}x{intrinsics.height}")
    u = np.arange(w, dtype=np.float32) + 0.5
    v = np.arange(h, dtype=np.float32) + 0.5
    z = np.where(depth > 0, depth, np.nan)
    x = (u[None, :] - intrinsics.cx) / intrinsics.fx * z
    y = (v[:, None] - intrinsics.cy) / intrinsics.fy * z
    return np.stack([x, y, z], axis=-1).astype(np.float32)


def project(points_cam: np.ndarray, intrinsics: CameraIntrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Project camera-frame points to pixels.

    Returns
    -------
    uv : (N, 2) float64 [px]; valid : (N,) bool — in front of the camera and inside the image.
    """
    p = np.asarray(points_cam, dtype=np.float64).reshape(-1, 3)
    z = p[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx * p[:, 0] / z + intrinsics.cx
        v = intrinsics.fy * p[:, 1] / z + intrinsics.cy
    valid = (z > 0) & (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
    return np.stack([u, v], axis=1), valid
