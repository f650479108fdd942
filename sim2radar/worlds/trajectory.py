"""Rig trajectories: walk the sensor rig along a world's corridor centre-line.

Frames are spread evenly along ``World.path_world`` (in either direction), with a small lateral
offset and a yaw that mostly follows the corridor and sometimes turns towards a door, as a
person carrying the rig would. Deterministic in (world, n_frames, seed).
"""

from __future__ import annotations

import math

import numpy as np

from sim2radar.worlds.frame import RigPose, World

__all__ = ["trajectory", "rig_pose", "rig_velocity"]


def rig_pose(x_m: float, y_m: float, yaw_rad: float, index: int = 0) -> RigPose:
    """A level rig pose at floor position (x, y) [m] looking along ``yaw_rad`` [rad]."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    m = np.array([[c, -s, 0, x_m], [s, c, 0, y_m], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=np.float64)
    return RigPose(m, index)


def trajectory(
    world: World,
    n_frames: int,
    seed: int = 0,
    *,
    max_lateral_m: float = 0.15,
    max_yaw_deg: float = 12.0,
    door_glance_probability: float = 0.3,
) -> list[RigPose]:
    """Rig poses along the corridor centre-line.

    Parameters
    ----------
    n_frames : int >= 1
    seed : int — trajectory seed (independent of the world seed).
    max_lateral_m : float [m] — largest sideways offset from the centre-line.
    max_yaw_deg : float [deg] — largest yaw jitter around the walking direction.
    door_glance_probability : float — chance that a frame turns up to 45° towards the nearest
        door ahead.

    Returns
    -------
    list[RigPose] — ``n_frames`` poses, ``index`` 0..n_frames-1.
    """
    if int(n_frames) < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    rng = np.random.default_rng([world.seed, int(seed), 7001])
    path = np.asarray(world.path_world, dtype=np.float64)
    if rng.uniform() < 0.5:
        path = path[::-1]
    seg = np.diff(path, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    total = cum[-1]
    span = total * 0.8
    start = rng.uniform(0.0, total - span) if total > span else 0.0
    stations = start + (np.arange(n_frames) + 0.5) / n_frames * span
    centers = np.array([d.center_world[:2] for d in world.doors]) if world.doors else None
    poses = []
    for i, s in enumerate(stations):
        k = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        direction = seg[k] / seg_len[k]
        p = path[k] + direction * (s - cum[k])
        normal = np.array([-direction[1], direction[0]])
        p = p + normal * rng.uniform(-max_lateral_m, max_lateral_m)
        yaw = math.atan2(direction[1], direction[0])
        yaw += math.radians(rng.uniform(-max_yaw_deg, max_yaw_deg))
        if centers is not None and rng.uniform() < door_glance_probability:
            rel = centers - p
            ahead = rel @ direction
            dist = np.linalg.norm(rel, axis=1)
            cand = np.flatnonzero((ahead > 1.0) & (dist < 8.0))
            if len(cand):
                j = cand[np.argmin(dist[cand])]
                target = math.atan2(rel[j, 1], rel[j, 0])
                delta = math.atan2(math.sin(target - yaw), math.cos(target - yaw))
                yaw += float(np.clip(delta, -math.radians(45), math.radians(45))) * 0.7
        poses.append(rig_pose(float(p[0]), float(p[1]), yaw, i))
    return poses


def rig_velocity(radar_to_world: np.ndarray, speed_mps: float) -> np.ndarray:
    """The radar's velocity in its own frame [m/s] for a rig moving at ``speed_mps`` along its
    heading: the radar's forward (x) axis projected onto the floor plane, in world coordinates,
    rotated into the radar frame (``R^T v``).

    Parameters
    ----------
    radar_to_world : (4, 4) — the frame's radar pose (rigid).
    speed_mps : float [m/s] >= 0.

    Returns
    -------
    (3,) float64 [m/s] — x forward, y left, z up (a level radar: ``(speed, 0, 0)``).
    """
    m = np.asarray(radar_to_world, dtype=np.float64)
    heading = np.array([m[0, 0], m[1, 0], 0.0])
    norm = float(np.linalg.norm(heading))
    if not norm > 1e-9:
        raise ValueError("the radar looks straight up or down: its heading is undefined")
    v_world = float(speed_mps) * heading / norm
    return m[:3, :3].T @ v_world
