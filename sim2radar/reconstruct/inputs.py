"""Input files of the reconstruction: an RGB image, a LiDAR ``.npy`` and the rig calibration
fields of an intrinsics YAML, read into what :class:`~sim2radar.reconstruct.FrameInput` takes.

Every loader raises :class:`~sim2radar.reconstruct.ReconstructionInputError` (a ``ValueError``)
whose message names the file, the field and the fix, so a flow records it as a failed scene and
a command prints it as one line.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from sim2radar.reconstruct.types import ReconstructionInputError, up_from_pitch_roll

__all__ = ["load_image", "load_lidar", "load_rig_calibration"]


def load_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file (PNG, JPEG, ...) as (H, W, 3) uint8 RGB."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise ReconstructionInputError(f"{path}: {_why_missing(path)}")
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise ReconstructionInputError(f"{path}: not a readable image (PNG/JPEG/...)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def _why_missing(path: Path) -> str:
    """Why ``path`` is not a readable file, in words a user can act on."""
    if path.is_symlink():
        try:
            target = path.resolve(strict=True)
        except (RuntimeError, OSError):
            return (f"is a symlink that does not lead to a file ({os.readlink(path)!r}: a loop or "
                    "a missing target); replace it with the image or a link to one")
        return f"is a symlink to {target}, which is not a file"
    return "image not found"


def load_lidar(path: str | os.PathLike, *, drop_invalid: bool = True) -> tuple[np.ndarray, str]:
    """Read an (N, >=3) ``.npy`` of LiDAR points in the camera frame [m] (OpenCV axes: x right,
    y down, z forward); return (points (N, 3) float32, note).

    Rows with NaN/inf are dropped and reported in ``note`` when ``drop_invalid``; otherwise
    they raise.
    """
    path = Path(path)
    if not path.is_file():
        raise ReconstructionInputError(f"{path}: LiDAR file not found")
    try:
        pts = np.load(path, allow_pickle=False)
    except Exception as exc:  # noqa: BLE001 - any read error is a bad file
        raise ReconstructionInputError(f"{path}: cannot read as .npy ({exc})") from None
    if pts.ndim != 2 or pts.shape[1] < 3 or not np.issubdtype(pts.dtype, np.number):
        raise ReconstructionInputError(
            f"{path}: LiDAR must be an (N, 3) numeric array of camera-frame points [m] (x right, "
            f"y down, z forward), got shape {pts.shape} {pts.dtype}"
        )
    pts = pts[:, :3].astype(np.float32)
    bad = ~np.isfinite(pts).all(axis=1)
    note = ""
    if bad.any():
        if not drop_invalid:
            raise ReconstructionInputError(f"{path}: {int(bad.sum())} LiDAR rows contain NaN/inf")
        pts = pts[~bad]
        note = f"dropped {int(bad.sum())} LiDAR rows with NaN/inf"
    return pts, note


def load_rig_calibration(path: str | os.PathLike) -> dict:
    """The optional rig calibration in an intrinsics YAML: ``camera_height_m`` (the camera's
    height above the floor [m]) and the camera's up — ``up_cam: [x, y, z]`` (camera frame: x
    right, y down, z forward) or ``camera_pitch_deg`` (down is positive) with
    ``camera_roll_deg`` (default 0) [deg]. Returns ``FrameInput`` keyword arguments (empty
    without any of them)."""
    from sim2radar.configio import read_yaml_mapping

    path = Path(path)
    doc = read_yaml_mapping(path, what="intrinsics file", error=ReconstructionInputError)
    out: dict = {}
    if "up_cam" in doc and "camera_pitch_deg" in doc:
        raise ReconstructionInputError(f"{path}: give the camera's up as up_cam or as "
                                       "camera_pitch_deg (+ camera_roll_deg), not both")
    try:
        if "up_cam" in doc:
            up = np.asarray(doc["up_cam"], np.float64)
            if up.shape != (3,):
                raise ValueError(f"up_cam must be [x, y, z], got {doc['up_cam']!r}")
            out["up_cam"] = up
        elif "camera_pitch_deg" in doc or "camera_roll_deg" in doc:
            out["up_cam"] = up_from_pitch_roll(float(doc.get("camera_pitch_deg", 0.0)),
                                               float(doc.get("camera_roll_deg", 0.0)))
        if "camera_height_m" in doc:
            out["camera_height_m"] = float(doc["camera_height_m"])
    except (TypeError, ValueError) as exc:
        raise ReconstructionInputError(f"{path}: rig calibration: {exc}") from None
    return out
