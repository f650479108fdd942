"""Stage 4a: back-projection, normals from depth, gravity, and the level camera frame.

Frames
------
camera : OpenCV (x right, y down, z forward) — :mod:`sim2radar.camera`.
level  : origin at the camera centre, x forward (optical axis projected on the horizontal plane),
    y left, z up (gravity-aligned; the radar/KITTI-LiDAR convention of DESIGN.md). Door boxes
    are fitted in this frame because their heading is a rotation about the vertical.
"""

from __future__ import annotations

import numpy as np

from sim2radar.camera import CameraIntrinsics, back_project

__all__ = [
    "points_from_depth",
    "normals_from_points",
    "estimate_up",
    "level_from_camera",
    "transform_points",
]


def points_from_depth(depth_m: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Back-project a z-depth image (pinhole model, ``camera.back_project``).

    Parameters
    ----------
    depth_m : (H, W) float — z-depth [m]; 0, negative or NaN where invalid.
    intrinsics : CameraIntrinsics — of this image.

    Returns
    -------
    (H, W, 3) float32 — camera-frame points [m]; NaN where the depth is invalid.
    X = (u − cx)·Z / fx, Y = (v − cy)·Z / fy at pixel centres (u, v) = (j + ½, i + ½).
    """
    depth = np.asarray(depth_m, dtype=np.float32)
    if depth.ndim != 2:
        raise ValueError(f"depth_m must be (H, W), got shape {depth.shape}")
    depth = np.where(np.isfinite(depth) & (depth > 0), depth, 0).astype(np.float32)
    return back_project(depth, intrinsics)


def normals_from_points(points: np.ndarray, step_px: int = 2) -> np.ndarray:
    """Surface normals from the gradients of a point grid.

    n = (P(i, j+s) − P(i, j−s)) × (P(i+s, j) − P(i−s, j)), normalised and turned to face the
    camera (n · P < 0). Pixels whose neighbours are invalid fall back to one-sided differences;
    pixels without any valid neighbour pair get NaN.

    Parameters
    ----------
    points : (H, W, 3) float — camera-frame points [m], NaN where invalid.
    step_px : int — half-width of the difference stencil [px]; larger is smoother.

    Returns
    -------
    (H, W, 3) float32 — unit normals (camera frame), NaN where unknown.
    """
    p = np.asarray(points, dtype=np.float64)
    s = int(step_px)
    pad = np.pad(p, ((s, s), (s, s), (0, 0)), constant_values=np.nan)
    h, w = p.shape[:2]
    right, left = pad[s:s + h, 2 * s:], pad[s:s + h, : w]
    down, up = pad[2 * s:, s:s + w], pad[: h, s:s + w]
    # central difference where both sides are valid, else one-sided
    dx = right - left
    dx = np.where(np.isnan(dx), right - p, dx)
    dx = np.where(np.isnan(dx), p - left, dx)
    dy = down - up
    dy = np.where(np.isnan(dy), down - p, dy)
    dy = np.where(np.isnan(dy), p - up, dy)
    n = np.cross(dx, dy)
    norm = np.linalg.norm(n, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = n / norm
    flip = np.sum(n * p, axis=-1) > 0
    n[flip] *= -1
    return n.astype(np.float32)


def estimate_up(normals: np.ndarray, max_tilt_deg: float = 30.0) -> np.ndarray:
    """Gravity "up" in the camera frame from the dominant horizontal planes (floor, ceiling).

    Assumes a roughly level camera (image "up" = −y within ``max_tilt_deg``): normals within that
    cone of ±y vote (ceiling normals point down and are flipped), their mean is refined once with
    a tighter cone. Falls back to (0, −1, 0) when fewer than 50 pixels vote.

    Returns
    -------
    (3,) float64 — unit up vector, camera frame.
    """
    n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
    n = n[np.isfinite(n).all(axis=1)]
    up = np.array([0.0, -1.0, 0.0])
    for cone in (max_tilt_deg, max_tilt_deg / 3):
        dots = n @ up
        votes = n[np.abs(dots) > np.cos(np.radians(cone))]
        if len(votes) < 50:
            break
        votes = votes * np.sign(votes @ up)[:, None]
        mean = votes.mean(axis=0)
        up = mean / np.linalg.norm(mean)
    return up


def level_from_camera(up_cam: np.ndarray) -> np.ndarray:
    """(4, 4) transform from the camera frame to the level frame (same origin).

    Rows of the rotation are the level axes expressed in camera coordinates:
    forward = optical axis minus its vertical component, left = up × forward, up.
    """
    up = np.asarray(up_cam, dtype=np.float64)
    up = up / np.linalg.norm(up)
    z = np.array([0.0, 0.0, 1.0])
    fwd = z - (z @ up) * up
    if np.linalg.norm(fwd) < 1e-6:
        raise ValueError("camera looks straight up or down; the level frame is undefined")
    fwd /= np.linalg.norm(fwd)
    left = np.cross(up, fwd)
    m = np.eye(4)
    m[:3, :3] = np.stack([fwd, left, up])
    return m


def transform_points(points: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """Apply a (4, 4) transform to (..., 3) points; NaNs stay NaN."""
    m = np.asarray(matrix, dtype=np.float64)
    p = np.asarray(points, dtype=np.float64)
    return (p @ m[:3, :3].T + m[:3, 3]).astype(np.float32)
