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

__all__ = ["MAX_IMAGE_PIXELS", "image_size", "load_image", "load_lidar", "load_rig_calibration",
           "max_image_pixels"]


#: The most pixels an input image may have (default 25 MP: a 6000 x 4000 camera); above it the
#: image is refused from its header, before it is decoded (a 1 MB PNG can declare 20000 x
#: 20000 = 1.2 GB of RGB, and the reconstruction's per-pixel arrays are ~20x that). Set
#: ``SIM2RADAR_MAX_IMAGE_PIXELS`` to change it.
MAX_IMAGE_PIXELS = 25_000_000


def max_image_pixels() -> int:
    """:data:`MAX_IMAGE_PIXELS`, or ``$SIM2RADAR_MAX_IMAGE_PIXELS`` when set."""
    raw = os.environ.get("SIM2RADAR_MAX_IMAGE_PIXELS", "").strip()
    if not raw:
        return MAX_IMAGE_PIXELS
    try:
        value = int(float(raw))
    except ValueError:
        raise ReconstructionInputError(f"$SIM2RADAR_MAX_IMAGE_PIXELS={raw!r} is not a number "
                                       "of pixels; set e.g. 25000000 or unset it") from None
    return value


def image_size(path: str | os.PathLike) -> tuple[int, int] | None:
    """``(width, height)`` of a PNG, JPEG or BMP file read from its header (a few hundred
    bytes, nothing decoded); None for another format or a header that does not parse."""
    import struct

    with open(path, "rb") as fh:
        head = fh.read(32)
        if head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR":
            return struct.unpack(">II", head[16:24])
        if head[:2] == b"BM" and len(head) >= 26:
            w, h = struct.unpack("<ii", head[18:26])
            return abs(w), abs(h)
        if head[:2] != b"\xff\xd8":
            return None
        fh.seek(2)
        while True:  # JPEG: walk the segments to the first start-of-frame marker
            marker = fh.read(2)
            if len(marker) < 2 or marker[0] != 0xFF:
                return None
            kind = marker[1]
            if kind in (0xD8, 0x01) or 0xD0 <= kind <= 0xD7:
                continue
            size = fh.read(2)
            if len(size) < 2:
                return None
            (length,) = struct.unpack(">H", size)
            if 0xC0 <= kind <= 0xCF and kind not in (0xC4, 0xC8, 0xCC):
                sof = fh.read(5)
                if len(sof) < 5:
                    return None
                h, w = struct.unpack(">HH", sof[1:5])
                return w, h
            fh.seek(length - 2, 1)


def load_image(path: str | os.PathLike) -> np.ndarray:
    """Read an image file (PNG, JPEG, ...) as (H, W, 3) uint8 RGB; one over
    :func:`max_image_pixels` is refused from its header, before decoding."""
    import cv2

    path = Path(path)
    if not path.is_file():
        raise ReconstructionInputError(f"{path}: {_why_missing(path)}")
    size = image_size(path)
    limit = max_image_pixels()
    if size is not None and size[0] * size[1] > limit:
        raise ReconstructionInputError(
            f"{path}: the image is {size[0]} x {size[1]} = {size[0] * size[1] / 1e6:.0f} MP, more "
            f"than the {limit / 1e6:.0f} MP an input may have (decoding and reconstructing it "
            "needs ~60 bytes per pixel: ~{:.0f} GB); downscale it (and its intrinsics), or raise "
            "$SIM2RADAR_MAX_IMAGE_PIXELS".format(size[0] * size[1] * 60 / 1e9))
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
