"""3D boxes ``x y z dx dy dz heading`` (``vocab.BOX_FIELDS``): frames, corners, point membership.

A box is upright: centre (x, y, z) [m], size dx along its heading, dy across it, dz up [m], and
heading [rad] about +z. This is the OpenPCDet/KITTI-LiDAR layout used for door labels in every
frame of the project (world, level, radar). All functions take and return NumPy arrays.
"""

from __future__ import annotations

import math

import numpy as np

#: Depth ``dy`` [m] of a doorway box through its wall when it is not measured. The procedural
#: worlds' doorway box spans the wall (0.10–0.20 m, ``WorldConfig.wall_thickness_m``) plus the
#: door frame's 1 cm lip on each face (:mod:`sim2radar.worlds.frame`): 0.17 m is the mean.
DOOR_THICKNESS_M = 0.17

__all__ = [
    "DOOR_THICKNESS_M",
    "as_boxes",
    "wrap_heading",
    "transform_boxes",
    "boxes_to_frame",
    "box_corners",
    "points_in_boxes",
    "boxes_in_view",
]


def as_boxes(boxes) -> np.ndarray:
    """(M, 7) float64 view of ``boxes`` (any (7,) or (M, 7) array-like, possibly empty)."""
    return np.asarray(boxes, dtype=np.float64).reshape(-1, 7)


def wrap_heading(heading_rad: np.ndarray, period: str = "half") -> np.ndarray:
    """Wrap headings to [-pi/2, pi/2) (``period="half"``: a box is the same after a half turn)
    or to [-pi, pi) (``period="full"``: keeps the direction a box faces)."""
    h = np.asarray(heading_rad, dtype=np.float64)
    if period == "half":
        return (h + np.pi / 2) % np.pi - np.pi / 2
    if period == "full":
        return (h + np.pi) % (2 * np.pi) - np.pi
    raise ValueError(f"period must be 'half' or 'full', got {period!r}")


def transform_boxes(boxes, matrix: np.ndarray, period: str = "half") -> np.ndarray:
    """Re-express boxes in another z-up frame.

    Parameters
    ----------
    boxes : (M, 7) [m, rad] in the source frame.
    matrix : (4, 4) — source frame -> target frame.
    period : heading wrap, see :func:`wrap_heading`.

    Returns
    -------
    (M, 7) float32. Centres are exact for any transform; the heading is rotated by the
    transform's yaw, which is exact when the rotation is about z (world, level and radar frames
    of an upright rig) and a small-angle approximation otherwise.
    """
    b = as_boxes(boxes).copy()
    m = np.asarray(matrix, dtype=np.float64)
    b[:, :3] = b[:, :3] @ m[:3, :3].T + m[:3, 3]
    b[:, 6] = wrap_heading(b[:, 6] + math.atan2(m[1, 0], m[0, 0]), period)
    return b.astype(np.float32)


def boxes_to_frame(boxes_world, sensor_to_world: np.ndarray, period: str = "half") -> np.ndarray:
    """World boxes in a sensor frame given the sensor's pose (4, 4) sensor -> world."""
    return transform_boxes(boxes_world, np.linalg.inv(np.asarray(sensor_to_world, np.float64)),
                           period)


def box_corners(boxes) -> np.ndarray:
    """(M, 8, 3) corners [m]; corner ``4*ix + 2*iy + iz`` has local signs (±dx/2, ±dy/2, ±dz/2)
    with index bit 0 = minus, 1 = plus."""
    b = as_boxes(boxes)
    signs = np.array([[sx, sy, sz] for sx in (-0.5, 0.5) for sy in (-0.5, 0.5)
                      for sz in (-0.5, 0.5)])
    local = signs[None] * b[:, None, 3:6]
    c, s = np.cos(b[:, 6])[:, None], np.sin(b[:, 6])[:, None]
    x = local[..., 0] * c - local[..., 1] * s
    y = local[..., 0] * s + local[..., 1] * c
    return np.stack([x, y, local[..., 2]], axis=-1) + b[:, None, :3]


def points_in_boxes(points, boxes, margin_m: float = 0.0) -> np.ndarray:
    """(N, M) bool: point n lies inside box m grown by ``margin_m`` on every side (boundaries
    included). ``points`` (N, >=3) x, y, z [m]."""
    p = np.asarray(points, dtype=np.float64).reshape(len(points), -1)[:, :3]
    b = as_boxes(boxes)
    if len(p) == 0 or len(b) == 0:
        return np.zeros((len(p), len(b)), dtype=bool)
    d = p[:, None, :] - b[None, :, :3]
    c, s = np.cos(b[:, 6]), np.sin(b[:, 6])
    along = d[..., 0] * c + d[..., 1] * s
    across = -d[..., 0] * s + d[..., 1] * c
    return ((np.abs(along) <= b[:, 3] / 2 + margin_m)
            & (np.abs(across) <= b[:, 4] / 2 + margin_m)
            & (np.abs(d[..., 2]) <= b[:, 5] / 2 + margin_m))


def boxes_in_view(boxes, az_fov_deg: float, el_fov_deg: float, max_range_m: float) -> np.ndarray:
    """(M,) bool: box centre in front of the sensor (x > 0), inside its full azimuth and
    elevation fields of view [deg] and within ``max_range_m`` [m] (sensor frame x fwd, y left,
    z up)."""
    c = as_boxes(boxes)[:, :3]
    az = np.arctan2(c[:, 1], c[:, 0])
    el = np.arctan2(c[:, 2], np.hypot(c[:, 0], c[:, 1]))
    return ((c[:, 0] > 0) & (np.abs(az) <= math.radians(az_fov_deg) / 2)
            & (np.abs(el) <= math.radians(el_fov_deg) / 2)
            & (np.linalg.norm(c, axis=1) <= max_range_m))
